# Copyright 2026 The pseudo_stereo_ros Authors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
The ``pseudo_stereo`` command line: one subcommand per module of :mod:`pseudo_stereo_ros.cli`.

Each command module defines ``NAME``, ``HELP``, ``add_arguments(parser)`` and
``run(args) -> int``.  Errors a user can fix
(:class:`~pseudo_stereo_ros.errors.PseudoStereoError` and its subclasses) print
one line naming the input and the reason and exit with status 2; nothing else
is caught, so bugs still show their traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from . import COMMAND_MODULES
from ..errors import PseudoStereoError

__all__ = ['main']


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser with every subcommand."""
    parser = argparse.ArgumentParser(
        prog='pseudo_stereo',
        description='Pseudo stereo vision for unsynchronized cameras (Shimizu et al.).')
    subparsers = parser.add_subparsers(dest='command', metavar='COMMAND', required=True)
    for module_name in COMMAND_MODULES:
        module = importlib.import_module(f'.{module_name}', __package__)
        sub = subparsers.add_parser(module.NAME, help=module.HELP, description=module.HELP)
        module.add_arguments(sub)
        sub.set_defaults(run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line; return the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.run(args) or 0)
    except PseudoStereoError as err:
        print(f'pseudo_stereo {args.command}: error: {err}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == '__main__':
    sys.exit(main())
