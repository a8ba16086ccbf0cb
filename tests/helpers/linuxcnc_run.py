"""LinuxCNC 2.9 for the tests, for real and headless (imported by the tests): install
orthocal's kinematics component where the installed one was built from another source,
start LinuxCNC on a machine configuration with tests/data/linuxcnc/mdi_display.py as its
display, which MDIs a list of targets and writes where the joints stood, and stop
everything it started, on success, failure or timeout alike.

- Root: LinuxCNC's rtapi_app refuses to run as root (uspace_rtapi_app.cc: it wants a
  fallback uid in RTAPI_UID), so as root (CI, in a fresh Debian container) LinuxCNC runs
  as ``nobody`` in a folder given to it; otherwise as ourselves.
- One at a time per machine: LinuxCNC's shared memory keys (HAL's, NML's), its TCP port
  and its /tmp/linuxcnc.lock are fixed, and its start script, finding that lock, stops
  the LinuxCNC that holds it. So a run holds :data:`LOCK` (pytest-xdist's workers take
  turns) and refuses to start beside a LinuxCNC that is not its own.
- Everything LinuxCNC starts carries a token in its environment, by which the run finds
  and stops what is left (rtapi_app leaves our process group: it calls setsid).
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import pwd
import re
import shutil
import signal
import subprocess
import tempfile
import time
import uuid
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from system import require

#: Held by whoever runs LinuxCNC or installs the component (all users, all workers).
LOCK = Path(tempfile.gettempdir()) / "orthocal-linuxcnc.lock"
LOCK_WAIT_S = 120.0
#: LinuxCNC's own lock: a LinuxCNC is up.
LINUXCNC_LOCK = Path("/tmp/linuxcnc.lock")
DISPLAY = Path(__file__).resolve().parents[1] / "data" / "linuxcnc" / "mdi_display.py"
EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "linuxcnc"
COMPONENT = "orthoglidekins"
START_S = 60.0  # from the start script to the machine homed in MDI
PER_TARGET_S = 3.0  # a move of the grid takes under a second
WAIT_S = 20.0  # the display's deadline for each thing it waits for
STOP_S = 40.0  # the start script's Cleanup waits up to 20 s per process
#: Shared memory of a running LinuxCNC: HAL, RTAPI, UUID (realtime's Unload) and NML
#: (linuxcnc.nml's buffers).
_SHM_KEYS = (0x48414C32, 0x90280A48, 0x48484C34, 1001, 1002, 1003, 1004, 1005)
_TOKEN = "ORTHOCAL_LINUXCNC_RUN"
_PATH = "/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin"


class LinuxCNCFailed(RuntimeError):
    """LinuxCNC did not do what the run asked; the message holds its log's end."""


@dataclass(frozen=True)
class Run:
    """Per target: the joints (``stat.joint[n]["output"]``, before screw
    compensation), the commanded and the actual tool point, the motors' commands
    (``joint.N.motor-pos-cmd``) and offsets (``joint.N.motor-offset``); the run's wall
    time from LinuxCNC's start to everything stopped."""

    joints: list[list[float]]
    position: list[list[float]]
    actual_position: list[list[float]]
    kinematics_type: int
    seconds: float
    motor: list[list[float]]
    motor_offset: list[list[float]]

    def motor_joints(self) -> list[list[float]]:
        """motor-pos-cmd less motor-offset: the joint commanded with its compensation."""
        return [[m - o for m, o in zip(ms, os_, strict=True)]
                for ms, os_ in zip(self.motor, self.motor_offset, strict=True)]


def available() -> bool:
    """LinuxCNC's start script, halcompile and Debian's python3-linuxcnc."""
    if not (shutil.which("linuxcnc", path=_PATH) and shutil.which("halcompile", path=_PATH)):
        return False
    # -I: Debian's python3-linuxcnc itself, not whatever the tests' path holds
    probe = subprocess.run(["/usr/bin/python3", "-I", "-c", "import linuxcnc"],
                           capture_output=True, timeout=30, check=False, env={"PATH": _PATH})
    return probe.returncode == 0


def require_linuxcnc() -> None:
    require(available(), "LinuxCNC 2.9 (linuxcnc, halcompile, python3-linuxcnc)")


@contextlib.contextmanager
def machine_lock() -> Iterator[None]:
    """The machine's one LinuxCNC, for this process, within LOCK_WAIT_S."""
    with open(LOCK, "a") as f:
        with contextlib.suppress(PermissionError):
            os.chmod(LOCK, 0o666)  # another user's tests take turns too
        deadline = time.monotonic() + LOCK_WAIT_S
        while True:
            try:
                fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() > deadline:
                    raise TimeoutError(f"{LOCK} held for over {LOCK_WAIT_S:.0f} s") from None
                time.sleep(0.2)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def component_source() -> str:
    return (resources.files("orthocal") / f"{COMPONENT}.comp").read_text(encoding="utf-8")


def installed_module() -> Path:
    """Where halcompile --install puts the component: LinuxCNC's module folder, as its
    start script names it."""
    script = Path(shutil.which("linuxcnc", path=_PATH) or "linuxcnc").read_text(errors="replace")
    found = re.search(r"^LINUXCNC_RTLIB_DIR=(\S+)$", script, re.M)
    return Path(found.group(1) if found else "/usr/lib/linuxcnc/modules") / f"{COMPONENT}.so"


def _tag(source: str) -> str:
    return "orthocal-source-sha256:" + hashlib.sha256(source.encode()).hexdigest()


def _is_current(module: Path, tag: str) -> bool:
    return module.is_file() and tag.encode() in module.read_bytes()


def install_component() -> None:
    """halcompile --install the component unless the installed module was built from
    this very source. A build is not reproducible byte for byte (debug paths), so the
    module carries the source's hash as a string (a line appended to the copy that is
    built) and that is compared. Needs root to install: without it, require()."""
    source = component_source()
    tag, module = _tag(source), installed_module()
    if _is_current(module, tag):
        return
    require(os.geteuid() == 0, f"root to install the {COMPONENT} component (halcompile "
            f"--install; or install it by hand: sudo halcompile --install {COMPONENT}.comp)")
    with machine_lock(), tempfile.TemporaryDirectory(prefix="orthocal-comp-") as folder:
        if _is_current(module, tag):  # another worker did it while we waited
            return
        comp = Path(folder) / f"{COMPONENT}.comp"
        comp.write_text(source + "\n/* which source this module was built from (tests) */\n"
                        f'static const char og_built_from[] __attribute__((used)) = "{tag}";\n',
                        encoding="utf-8")
        built = subprocess.run(["halcompile", "--install", str(comp)], cwd=folder, text=True,
                               capture_output=True, timeout=180, check=False,
                               env={"PATH": _PATH, "LANG": "C"})
        if built.returncode != 0 or not _is_current(module, tag):
            raise LinuxCNCFailed(f"halcompile --install failed:\n{built.stdout}{built.stderr}")


def mdi(config: Path, targets: Sequence[Sequence[float]], ini: str = "orthoglide.ini",
        feed: float | None = None) -> Run:
    """Start LinuxCNC on ``config/ini`` (a folder of an INI and its HAL files, copied),
    MDI every target (G0, or G1 at ``feed`` mm/min) and stop it; what the display
    recorded per target. LinuxCNCFailed when it could not."""
    require_linuxcnc()
    install_component()
    with machine_lock(), _run_folder(config) as folder:
        began = time.monotonic()
        _refuse_a_foreign_linuxcnc()
        _prepare(folder, ini, targets, feed)
        _start_and_wait(folder, ini, START_S + PER_TARGET_S * len(targets))
        results = json.loads((folder / "mdi_results.json").read_text(encoding="utf-8"))
        seconds = time.monotonic() - began
    if results["error"] is not None:
        raise LinuxCNCFailed(f"the MDI display failed: {results['error']}")
    points = results["points"]
    return Run([p["joints"] for p in points], [p["position"] for p in points],
               [p["actual_position"] for p in points], results["kinematics_type"], seconds,
               [p["motor"] for p in points], [p["motor_offset"] for p in points])


def _runs_as() -> pwd.struct_passwd | None:
    """The user LinuxCNC runs as: ``nobody`` where we are root, else ourselves (None)."""
    return pwd.getpwnam("nobody") if os.geteuid() == 0 else None


@contextlib.contextmanager
def _run_folder(config: Path) -> Iterator[Path]:
    """A copy of ``config`` LinuxCNC's user owns (it writes its parameter file there)."""
    root = Path(tempfile.mkdtemp(prefix="orthocal-linuxcnc-"))
    try:
        folder = root / "config"
        shutil.copytree(config, folder)
        shutil.copy(DISPLAY, folder / DISPLAY.name)
        (folder / DISPLAY.name).chmod(0o755)
        user = _runs_as()
        if user is not None:
            for path in (root, folder, *folder.rglob("*")):
                os.chown(path, user.pw_uid, user.pw_gid)
        root.chmod(0o755)
        yield folder
    finally:
        shutil.rmtree(root, ignore_errors=True)


def _prepare(folder: Path, ini: str, targets: Sequence[Sequence[float]],
             feed: float | None) -> None:
    """The display in the INI's [DISPLAY] section, the job beside it."""
    path = folder / ini
    lines, section = [], ""
    for line in path.read_text(encoding="utf-8").splitlines():
        if m := re.match(r"\s*\[([^\]]+)\]", line):
            section = m.group(1).strip()
        if section == "DISPLAY" and re.match(r"\s*DISPLAY\s*=", line):
            line = f"DISPLAY = {folder / DISPLAY.name}"
        lines.append(line)
    if f"DISPLAY = {folder / DISPLAY.name}" not in lines:
        raise ValueError(f"{ini}: no [DISPLAY] DISPLAY line to point at the MDI display")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    job = {"targets": [[float(v) for v in t] for t in targets], "feed": feed,
           "timeout_s": WAIT_S}
    (folder / "mdi_job.json").write_text(json.dumps(job), encoding="utf-8")
    user = _runs_as()
    if user is not None:
        os.chown(folder / "mdi_job.json", user.pw_uid, user.pw_gid)


def _refuse_a_foreign_linuxcnc() -> None:
    """Under LOCK no LinuxCNC of ours runs: any sign of one is someone else's, which our
    start would stop (its script cleans up the other instance)."""
    present = [hex(key) for key, _ in _segments() if key in _SHM_KEYS]
    require(not LINUXCNC_LOCK.exists() and not present,
            f"no LinuxCNC running already ({LINUXCNC_LOCK} or shared memory {present})")


def _start_and_wait(folder: Path, ini: str, timeout_s: float) -> None:
    """Run LinuxCNC's start script until its display has exited (it then stops
    LinuxCNC itself), at most ``timeout_s``; then make sure nothing of it is left."""
    token = uuid.uuid4().hex
    user = _runs_as()
    name = user.pw_name if user is not None else pwd.getpwuid(os.geteuid()).pw_name
    env = {"PATH": _PATH, "HOME": str(folder), "USER": name, "LOGNAME": name, "LANG": "C",
           _TOKEN: token}
    as_user = {} if user is None else {"user": user.pw_uid, "group": user.pw_gid,
                                       "extra_groups": []}
    log = folder / "linuxcnc.log"
    with open(log, "wb") as out:  # -r: its output here, not in files of its own
        proc = subprocess.Popen(["linuxcnc", "-r", str(folder / ini)], cwd=folder, env=env,
                                stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True, **as_user)
    try:
        proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        raise LinuxCNCFailed(f"LinuxCNC still running after {timeout_s:.0f} s\n"
                             + _tail(log)) from None
    finally:
        left = _stop(proc, token)
    if left:
        raise LinuxCNCFailed(f"left behind after stopping LinuxCNC: {left}\n" + _tail(log))
    if not (folder / "mdi_results.json").is_file():
        raise LinuxCNCFailed(f"LinuxCNC exited ({proc.returncode}) without results\n"
                             + _tail(log))


def _tail(log: Path, lines: int = 40) -> str:
    try:
        return "\n".join(log.read_text(errors="replace").splitlines()[-lines:])
    except OSError:
        return "(no log)"


def _stop(proc: subprocess.Popen[bytes], token: str) -> list[str]:
    """Stop the start script (SIGTERM: its trap runs LinuxCNC's Cleanup; then SIGKILL),
    then whatever carries the token, then the shared memory nothing uses any more and
    LinuxCNC's lock file. What is still left, in words (nothing, normally)."""
    if proc.poll() is None:
        _signal_group(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=STOP_S)
        except subprocess.TimeoutExpired:
            _signal_group(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)
    for sig in (signal.SIGTERM, signal.SIGKILL):
        pids = _carrying(token)
        for pid in pids:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, sig)
        deadline = time.monotonic() + 5.0
        while pids and _carrying(token) and time.monotonic() < deadline:
            time.sleep(0.1)
    for key, attached in _segments():
        if key in _SHM_KEYS and attached == 0:
            subprocess.run(["ipcrm", "-M", f"{key:#x}"], capture_output=True, timeout=10,
                           check=False)
    with contextlib.suppress(FileNotFoundError, PermissionError):
        LINUXCNC_LOCK.unlink()  # under LOCK, refused if there before: ours
    return leftovers(token)


def leftovers(token: str | None = None) -> list[str]:
    """What a stopped LinuxCNC must not leave: processes carrying the run's token,
    LinuxCNC's shared memory, its lock file."""
    out = [f"process {pid} ({_name(pid)})" for pid in (_carrying(token) if token else [])]
    out += [f"shared memory {key:#x}" for key, _ in _segments() if key in _SHM_KEYS]
    return out + ([str(LINUXCNC_LOCK)] if LINUXCNC_LOCK.exists() else [])


def _signal_group(pid: int, sig: signal.Signals) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pid, sig)


def _carrying(token: str) -> list[int]:
    """Live processes (zombies are gone, only not yet reaped) with the token in their
    environment; rtapi_app among them, though it made a session of its own."""
    mark = f"{_TOKEN}={token}".encode()
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            environ = (entry / "environ").read_bytes().split(b"\0")
            state = (entry / "stat").read_text().rsplit(")", 1)[1].split()[0]
        except (OSError, IndexError):
            continue
        if mark in environ and state != "Z":
            found.append(int(entry.name))
    return found


def _name(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/comm").read_text().strip()
    except OSError:
        return "?"


def _segments() -> list[tuple[int, int]]:
    """(key, processes attached) of every System V shared memory segment."""
    try:
        rows = Path("/proc/sysvipc/shm").read_text().splitlines()[1:]
    except OSError:
        return []
    return [(int(r.split()[0]) & 0xFFFFFFFF, int(r.split()[6])) for r in rows if r.strip()]
