"""A Python without the POSIX-only modules, as a shop's Windows PC has none of them:
``fcntl``, ``termios``, ``pty`` and ``tty`` cannot be imported, by the station or by
anything it loads.

:func:`argv` gives the command line of such a Python running ``code``: a meta-path
finder installed first refuses exactly those names (none of them is loaded at start-up,
which it checks), so an ``import`` of one anywhere raises ImportError as it would on
Windows.

One library decides by ``os.name`` rather than by what imports: pyserial loads the
backend of the platform's own serial ports when it is imported (``serialposix`` here,
which needs fcntl and termios; ``serialwin32`` on Windows, which needs neither). With
``serial_backend`` that backend is replaced by one that opens no port at all (a port
path fails to open, as a device that is not there), so that ``import serial`` goes on
as on Windows; URL ports (``socket://``) are pyserial's own URL handlers, unchanged.
"""

from __future__ import annotations

import sys

#: What a Python on Windows lacks, of what the station could import.
BLOCKED = ("fcntl", "termios", "pty", "tty")

#: filelock says once, as it is imported, that it has only its marker lock where
#: fcntl is missing; that is the point here, not news.
_QUIET = "ignore:only soft file lock is available:UserWarning"

_FINDER = f'''
import sys
BLOCKED = frozenset({BLOCKED!r})
assert not BLOCKED & set(sys.modules), f"already loaded: {{sorted(BLOCKED & set(sys.modules))}}"


class _NotOnThisPlatform:
    def find_spec(self, name, path=None, target=None):
        if name in BLOCKED:
            raise ImportError(f"No module named {{name!r}}", name=name)
        return None


sys.meta_path.insert(0, _NotOnThisPlatform())
'''

_SERIAL_BACKEND = r'''
import types


class _NoNativePorts(types.ModuleType):
    """Stands in for pyserial's backend of the platform's own ports (module docstring
    of tests/helpers/no_posix.py): its classes open nothing."""

    def __getattr__(self, name):
        if name not in ("Serial", "PosixPollSerial", "VTIMESerial"):
            raise AttributeError(name)
        util = sys.modules["serial.serialutil"]

        def refuse(port):
            raise util.SerialException(f"could not open port {port.port}: no such device")

        return type(name, (util.SerialBase,), {"open": refuse})


sys.modules["serial.serialposix"] = _NoNativePorts("serial.serialposix")
'''


def prelude(serial_backend: bool = False) -> str:
    """The code that makes this Python one without the POSIX-only modules."""
    return _FINDER + (_SERIAL_BACKEND if serial_backend else "")


def argv(code: str, *args: str, serial_backend: bool = False) -> list[str]:
    """``python -c`` running ``code`` (with ``args`` in sys.argv[1:]) without them."""
    return [sys.executable, "-W", _QUIET, "-c", prelude(serial_backend) + code, *args]


#: Code that prints, as its last line, the POSIX-only modules loaded after all.
REPORT_LOADED = r'''
print("loaded:" + ",".join(sorted(BLOCKED & set(sys.modules))), flush=True)
'''
