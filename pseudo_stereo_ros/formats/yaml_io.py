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
Small YAML configuration files (calibrations, detector parameters), read safely.

:func:`read_yaml` reads a file of at most ``max_bytes`` as UTF-8 and parses
it with PyYAML's safe loader, refusing before anything expands:

- **aliases** (``*name``): the first one is refused while parsing, so an
  alias bomb (a kilobyte that expands to billions of values) costs
  microseconds.  Configuration files written by people or by
  camera_calibration never need them; anchors alone are harmless.
- **nesting** deeper than ``max_depth`` levels (PyYAML's composer recurses
  once per level: 20,000 levels would be a RecursionError).
- **files over** ``max_bytes``: a bag or an image given by mistake.

Every failure is one line, ``<file>:<line>:<column>: <reason>`` (or
``<file>: <reason>``), raised as the caller's error class.  ROS-free.
"""

from __future__ import annotations

import os
from typing import Any, TYPE_CHECKING

import yaml
from yaml.composer import ComposerError
from yaml.constructor import ConstructorError
from yaml.scanner import ScannerError

from ..errors import PseudoStereoError

if TYPE_CHECKING:  # calibration imports this module: the alias is for the type checker only
    from ..calibration import PathLike

__all__ = ['DEFAULT_MAX_BYTES', 'DEFAULT_MAX_DEPTH', 'read_yaml', 'yaml_error_line']

#: Largest file read [bytes]: calibration and parameter files are a few kB.
DEFAULT_MAX_BYTES = 1 << 20
#: Deepest nesting of collections (a calibration needs 3: mapping, matrix, rows).
DEFAULT_MAX_DEPTH = 32


class _LimitedLoader(yaml.SafeLoader):
    """PyYAML's safe loader without aliases and with a depth limit, checked while composing."""

    max_depth = DEFAULT_MAX_DEPTH

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0

    def compose_node(self, parent: yaml.Node | None, index: int) -> yaml.Node | None:
        event = self.peek_event()
        if isinstance(event, yaml.AliasEvent):
            # types-PyYAML types an event's mark as the C or the Python loader's; this
            # pure-Python loader's marks are yaml.error.Mark, as ComposerError expects.
            raise ComposerError(None, None, f'found the alias *{event.anchor}: aliases are not '
                                'allowed here (write the values out)',
                                event.start_mark)  # type: ignore[arg-type]
        self._depth += 1
        try:
            if self._depth > self.max_depth:
                raise ComposerError(None, None,
                                    f'nested deeper than {self.max_depth} levels',
                                    event.start_mark)
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def fetch_flow_collection_start(self, token_class: type[yaml.Token]) -> None:
        # Refuse deep flow nesting while scanning: the scanner looks up to 1,024 characters
        # ahead for a possible key at every level, which the composer's check comes too late for.
        if self.flow_level >= self.max_depth:
            raise ScannerError(None, None, f'nested deeper than {self.max_depth} levels',
                               self.get_mark())
        super().fetch_flow_collection_start(token_class)

    def construct_object(self, node: yaml.Node, deep: bool = False) -> Any:
        try:
            return super().construct_object(node, deep=deep)
        except (ValueError, TypeError, OverflowError) as err:
            # A value of a resolved type that does not hold (2001-13-45, !!int abc): PyYAML
            # raises these without a position.
            raise ConstructorError(None, None, f'cannot read the value: {err}',
                                   node.start_mark) from err


def yaml_error_line(err: yaml.YAMLError, text: str = '') -> str:
    """
    Return a PyYAML error as one line: ``<line>:<column>: <problem> (<context>)``.

    PyYAML's own message spans two to five lines (the problem, a mark, the
    offending source line and a caret).

    :param err: the error
    :param text: the parsed text (gives the line of a reader error, which has only an offset)
    :return: the line; it starts with the 1-based ``line:column:`` when the error has a
        position, and says ``not valid YAML``
    """
    if isinstance(err, yaml.reader.ReaderError):
        line = text.count('\n', 0, err.position) + 1
        column = err.position - (text.rfind('\n', 0, err.position) + 1) + 1
        character = (f'#x{err.character:04x}' if isinstance(err.character, int)
                     else repr(err.character))
        return (f'{line}:{column}: not valid YAML: unacceptable character {character} '
                f'({err.reason})')
    if isinstance(err, yaml.MarkedYAMLError):
        mark = err.problem_mark or err.context_mark
        reason = err.problem or err.context or 'syntax error'
        if err.context and err.problem:
            where = ''
            if err.context_mark is not None and err.context_mark is not mark:
                where = (f' at line {err.context_mark.line + 1}, '
                         f'column {err.context_mark.column + 1}')
            reason = f'{reason} ({err.context}{where})'
        prefix = f'{mark.line + 1}:{mark.column + 1}: ' if mark is not None else ''
        return f'{prefix}not valid YAML: {reason}'
    return 'not valid YAML: ' + ' '.join(str(err).split())


def read_yaml(path: PathLike, *, error: type[PseudoStereoError] = PseudoStereoError,
              max_bytes: int = DEFAULT_MAX_BYTES,
              max_depth: int = DEFAULT_MAX_DEPTH) -> tuple[Any, yaml.Node | None]:
    """
    Read and parse a small YAML file without aliases.

    :param path: the file
    :param error: the error class to raise (e.g. ``CalibrationError``)
    :param max_bytes: refuse a larger file unread [bytes]
    :param max_depth: refuse deeper nesting of collections
    :return: ``(data, node)``: the document as ``yaml.safe_load`` builds it, and its node
        tree (scalars exactly as written: a numeric name keeps its leading zeros), both None
        for an empty file
    :raises PseudoStereoError: (the given subclass) one line naming the file and the reason,
        with the line and column where the text is at fault
    """
    source = os.fspath(path)
    try:
        with open(path, 'rb') as stream:
            raw = stream.read(max_bytes + 1)
    except OSError as err:
        raise error(f'{source}: cannot read: {err.strerror}') from err
    if len(raw) > max_bytes:
        raise error(f'{source}: larger than {max_bytes} bytes: not a configuration file')
    try:
        text = raw.decode('utf-8-sig')
    except UnicodeDecodeError as err:
        line = raw.count(b'\n', 0, err.start) + 1
        raise error(f'{source}:{line}: not UTF-8 text (byte 0x{raw[err.start]:02x} at offset '
                    f'{err.start})') from err
    loader_class = type('Loader', (_LimitedLoader,), {'max_depth': max_depth})
    try:
        loader = loader_class(text)  # checks for unprintable characters
        try:
            node = loader.get_single_node()
            data = loader.construct_document(node) if node is not None else None
        finally:
            loader.dispose()
    except yaml.YAMLError as err:
        reason = yaml_error_line(err, text)
        raise error(f'{source}:{reason}' if reason[0].isdigit() else f'{source}: {reason}') \
            from err
    return data, node
