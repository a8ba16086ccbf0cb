"""``orthocal schema result|journal``: the JSON Schema of the run's documents, for
the tools that read them (docs/design.md, "The run record")."""

from __future__ import annotations

import argparse
import sys


def main(args: argparse.Namespace) -> int:
    from station.record.schema_files import dumps

    sys.stdout.write(dumps(args.kind))
    return 0
