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
Shared glue of the package's nodes: parameters, the Jazzy ``main()`` pattern and graph checks.

A node's ``__init__`` raises :class:`StartupError` (or a
:class:`~pseudo_stereo_ros.calibration.CalibrationError`, or rclpy's
parameter exceptions, or rclpy's name validation) for a bad parameter or
file; :func:`run_node` logs the message, which names the parameter, as one
FATAL line and returns exit status 1.  A params file that is missing or that
rcl cannot parse (``--ros-args --params-file F``), or another bad ROS
argument, is reported the same way by :func:`init_context`, before
``rclpy.init`` and without rcl's own error line.

Every executable spins through :func:`spin` and cleans up through
:func:`close`: one loop that ends on SIGINT/SIGTERM, on a condition or at
a deadline, with rclpy's ``EventsExecutor`` by default (:data:`EXECUTORS`).
``EventsExecutor`` dispatches each message from a C++ event queue instead of
rebuilding a wait set for every callback: measured here, a subscriber with
the ``SingleThreadedExecutor`` lost messages from 5,000 messages/s on,
with ``EventsExecutor`` none at 12,700 messages/s.

A params file is not checked by rcl against the parameters a node declares:
a misspelt key (``sync_tolerence_s``) or node name (``/**/fusr``) would
start the node silently on its defaults.  :func:`check_params_files` warns
with one line per unknown key, naming the nearest known name.
"""

import difflib
import os
import re
import sys
import time
from typing import Callable, Dict, Iterable, List, Optional, Sequence, Tuple

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
import rclpy
from rclpy.exceptions import (InvalidParameterTypeException, InvalidParameterValueException,
                              NameValidationException, ParameterException,
                              ParameterUninitializedException)
from rclpy.executors import (Executor, ExternalShutdownException, MultiThreadedExecutor,
                             SingleThreadedExecutor)
from rclpy.experimental import EventsExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
import rclpy.logging
from rclpy.node import Node
import rclpy.utilities
import yaml

from ..camera import Camera
from ..detection import BallDetector, CHOICES
from ..errors import CalibrationError, RigError, StartupError
from ..rig import check_camera_name, config_dir, Rig

__all__ = [
    'DEFAULT_EXECUTOR',
    'EXECUTORS',
    'PublisherWatch',
    'StartupError',
    'check_camera_names',
    'check_params_files',
    'close',
    'declare',
    'declare_detector',
    'init_context',
    'load_cameras',
    'logger_name',
    'make_executor',
    'one_line',
    'params_files',
    'run_node',
    'spin',
    'split_executor_option',
]

#: Executor kinds: ``events`` (rclpy.experimental.EventsExecutor, the default: a C++ event
#: queue), ``single`` (SingleThreadedExecutor), ``multi`` (MultiThreadedExecutor).
EXECUTORS = ('events', 'single', 'multi')
DEFAULT_EXECUTOR = 'events'

#: Exceptions that mean "bad configuration": the node stops at start-up with the message.
STARTUP_ERRORS = (CalibrationError, InvalidParameterTypeException,
                  InvalidParameterValueException, NameValidationException, ParameterException,
                  ParameterUninitializedException, ValueError, FileNotFoundError)


def declare(node: Node, name: str, default, description: str, *,
            min_value: Optional[float] = None, max_value: Optional[float] = None,
            choices: Optional[Sequence[str]] = None, read_only: bool = False):
    """
    Declare one parameter with a descriptor and return its value.

    :param node: the node
    :param name: the parameter name (units in the name: ``_s``, ``_m``, ``_px``)
    :param default: the default value; its type is the parameter's type
    :param description: what it is, with its unit
    :param min_value: lowest allowed number (a range in the descriptor, checked by rclpy)
    :param max_value: highest allowed number
    :param choices: allowed strings (listed in ``additional_constraints``, checked here)
    :param read_only: the parameter cannot change after start-up
    :return: the value (overrides and parameter files applied)
    :raises StartupError: a value outside ``choices``
    """
    descriptor = ParameterDescriptor(description=description, read_only=read_only)
    if choices is not None:
        descriptor.additional_constraints = 'one of: ' + ', '.join(choices)
    if min_value is not None or max_value is not None:
        if isinstance(default, float):
            descriptor.floating_point_range = [FloatingPointRange(
                from_value=float(-sys.float_info.max if min_value is None else min_value),
                to_value=float(sys.float_info.max if max_value is None else max_value))]
        else:
            descriptor.integer_range = [IntegerRange(
                from_value=int(-2 ** 63 if min_value is None else min_value),
                to_value=int(2 ** 63 - 1 if max_value is None else max_value), step=0)]
    value = node.declare_parameter(name, default, descriptor).value
    if choices is not None and value not in choices:
        raise StartupError(f'parameter {name!r}: {value!r} is not one of {", ".join(choices)}')
    return value


def check_camera_names(camera_names: Sequence[str], *, minimum: int = 2) -> List[str]:
    """
    Check the ``camera_names`` parameter: enough names, each a ROS name token, none repeated.

    :param camera_names: the parameter's value
    :param minimum: the least number of names
    :return: the names
    :raises StartupError: ``parameter camera_names: ...`` with the rule
        (:func:`~pseudo_stereo_ros.rig.check_camera_name`)
    """
    names = list(camera_names or [])
    if len(names) < minimum:
        raise StartupError(f'parameter camera_names: need at least {minimum} camera names, '
                           f'got {names}')
    try:
        for name in names:
            check_camera_name(name)
    except RigError as err:
        raise StartupError(f'parameter camera_names: {err}') from err
    return names


def declare_detector(node: Node) -> BallDetector:
    """
    Declare the ball detector's parameters on a node and return the detector they configure.

    Shared by the ``detector`` and ``camera_detector`` nodes, so both take the same
    parameters (``hsv_lower``, ``hsv_upper``, ``mono_threshold``, ``min_area_px``,
    ``max_area_px``, ``open_kernel_px``, ``choice``, ``search_window_px``).

    :param node: the node
    :return: the detector
    :raises StartupError: a value the detector refuses, naming the parameters
    """
    hsv_lower = declare(node, 'hsv_lower', [5, 120, 100],
                        'lowest ball colour (H 0..179, S, V 0..255), OpenCV HSV')
    hsv_upper = declare(node, 'hsv_upper', [25, 255, 255],
                        'highest ball colour (H, S, V); lower H > upper H wraps around red')
    mono_threshold = declare(node, 'mono_threshold', 200,
                             'mono8 images: a ball pixel is at least this bright',
                             min_value=0, max_value=255)
    min_area = declare(node, 'min_area_px', 4.0, 'smallest ball blob area [px]', min_value=0.0)
    max_area = declare(node, 'max_area_px', 20000.0, 'largest ball blob area [px]',
                       min_value=0.0)
    open_kernel = declare(node, 'open_kernel_px', 3,
                          'morphological opening kernel size [px]; 0 disables',
                          min_value=0, max_value=31)
    choice = declare(node, 'choice', 'largest', 'which blob when there are several',
                     choices=CHOICES)
    window = declare(node, 'search_window_px', 48,
                     'half side of the search window around the last detection [px]; '
                     '0: always the full frame', min_value=0)
    try:
        return BallDetector(
            hsv_lower=hsv_lower, hsv_upper=hsv_upper, mono_threshold=mono_threshold,
            min_area_px=min_area, max_area_px=max_area, open_kernel_px=open_kernel,
            choice=choice, search_window_px=window)
    except (ValueError, TypeError) as err:
        raise StartupError(f'detector parameters (hsv_lower, hsv_upper, min_area_px, '
                           f'max_area_px, ...): {err}') from err


def load_cameras(camera_names: Sequence[str], calibration_files: Sequence[str]) -> List[Camera]:
    """
    Load the cameras named by the ``camera_names`` and ``calibration_files`` parameters.

    :param camera_names: at least two unique names, each a ROS name token
    :param calibration_files: one file per name (same order), or empty for the default rig's
        ``config/rig/<name>.yaml``
    :return: the cameras
    :raises StartupError: naming the parameter and the reason; for a missing or malformed
        calibration file also the entry, and the file and key (from the
        :class:`~pseudo_stereo_ros.calibration.CalibrationError`)
    """
    names = check_camera_names(camera_names)
    files = list(calibration_files or []) or [
        str(config_dir() / 'rig' / f'{name}.yaml') for name in names]
    if len(files) != len(names):
        raise StartupError(f'parameter calibration_files: {len(files)} files for '
                           f'{len(names)} camera_names (one per camera, same order)')
    cameras = []
    for index, (name, path) in enumerate(zip(names, files)):
        try:
            # The topic name is what the fuser matches on; keep the file's intrinsics and pose.
            cameras.append(Camera.from_file(path, name=name))
        except CalibrationError as err:
            raise StartupError(f'parameter calibration_files[{index}] (camera {name}): '
                               f'{err}') from err
    try:
        return Rig(cameras).cameras
    except RigError as err:
        raise StartupError(f'parameter camera_names: {err}') from err


def logger_name(default_name: str, args: Optional[Sequence[str]] = None) -> str:
    """
    Return the logger name of a node as rclpy names it (``namespace.name``), before it exists.

    Remappings of ``__node`` / ``__name`` and ``__ns`` in ``args`` are applied, so start-up
    errors carry the same name as the node's own log lines (``[camera1.detector]``).

    :param default_name: the node's name without remapping (``'fuser'``)
    :param args: command-line arguments (``--ros-args -r __ns:=/camera1 ...``); None for
        ``sys.argv``
    :return: the logger name
    """
    argv = list(sys.argv if args is None else args)
    name, namespace = default_name, ''
    for flag, rule in zip(argv, argv[1:]):
        if flag in ('-r', '--remap') and ':=' in rule:
            key, value = rule.split(':=', 1)
            if key in ('__node', '__name'):
                name = value
            elif key == '__ns':
                namespace = value
    return '.'.join(part for part in namespace.split('/') + [name] if part)


def _default_node_name(node_factory: Callable[..., Node]) -> str:
    """Return ``fuser`` for ``FuserNode``, ``virtual_camera`` for ``VirtualCameraNode``."""
    class_name = getattr(node_factory, '__name__', 'node')
    if class_name.endswith('Node') and class_name != 'Node':
        class_name = class_name[:-len('Node')]
    return re.sub(r'(?<!^)(?=[A-Z])', '_', class_name).lower()


def one_line(text: str) -> str:
    """
    Return an error message as one line.

    rcl appends ``, at <source file>:<line>`` frames; rclpy's name validation adds the name
    and a caret on lines of their own.  Both are noise in a start-up error.
    """
    text = re.sub(r', at \S+:\d+', '', str(text))
    lines = [line.strip() for line in text.splitlines() if line.strip().strip('^')]
    return ' '.join(lines)


def _ros_arguments_error(args: Optional[List[str]]) -> Optional[str]:
    """
    Parse the ROS arguments as ``rclpy.init`` will, quietly; return why they are bad, or None.

    rcl logs its own ``Failed to parse global arguments`` line before rclpy raises, and a
    missing params file is only ``Error opening YAML file``: parsing once with rcl's logger
    silenced leaves one line, ours.
    """
    argv = list(sys.argv if args is None else args)
    ros = False
    for flag, value in zip(argv, argv[1:]):
        if flag == '--ros-args':
            ros = True
        elif flag == '--':
            ros = False
        elif ros and flag == '--params-file' and not os.path.isfile(value):
            return f'--params-file {value}: no such file'
        elif ros and flag == '--params-file' and not os.access(value, os.R_OK):
            return f'--params-file {value}: not readable'
    rcl_logger = rclpy.logging.get_logger('rcl')
    rcl_logger.set_level(rclpy.logging.LoggingSeverity.FATAL)
    try:
        rclpy.utilities.remove_ros_args(argv)
    except _rclpy.RCLError as err:
        return one_line(err)
    except _rclpy.UnknownROSArgsError as err:
        return f'unknown ROS argument(s): {one_line(err)}'
    finally:
        rcl_logger.set_level(rclpy.logging.LoggingSeverity.UNSET)
    return None


def init_context(args: Optional[List[str]] = None, *, context=None,
                 name: str = 'node') -> bool:
    """
    Run ``rclpy.init``; on failure (a missing or bad params file or argument) log one line.

    :param args: command-line arguments (``--ros-args ...``); None for ``sys.argv``
    :param context: the context to initialize; None for the default one
    :param name: the logger name for the message (see :func:`logger_name`)
    :return: True when initialized; False after logging ``cannot start: <reason>``, the only
        line (rcl's own error line is silenced)
    """
    reason = _ros_arguments_error(args)
    if reason is None:
        try:
            rclpy.init(args=args, context=context)
        except _rclpy.RCLError as err:
            reason = one_line(err)
    if reason is not None:
        rclpy.logging.get_logger(name).fatal(f'cannot start: {reason}')
        return False
    return True


def make_executor(kind: str = DEFAULT_EXECUTOR, *, context=None) -> Executor:
    """
    Return an executor of the given kind (one of :data:`EXECUTORS`).

    :param kind: ``events``, ``single`` or ``multi``
    :param context: the context; None for the default one
    :return: the executor
    :raises StartupError: an unknown kind
    """
    if kind == 'events':
        return _events_executor(context)
    if kind == 'single':
        return SingleThreadedExecutor(context=context)
    if kind == 'multi':
        return MultiThreadedExecutor(context=context)
    raise StartupError(f'--executor {kind}: not one of {", ".join(EXECUTORS)}')


def _events_executor(context) -> Executor:
    """Return rclpy's EventsExecutor, also when ``sys.stderr`` is not a file (captured)."""
    # Its constructor enables faulthandler on sys.stderr, which needs a file descriptor.
    try:
        sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):
        if sys.__stderr__ is None:
            return SingleThreadedExecutor(context=context)
        captured, sys.stderr = sys.stderr, sys.__stderr__
        try:
            return EventsExecutor(context=context)
        finally:
            sys.stderr = captured
    return EventsExecutor(context=context)


def split_executor_option(args: Optional[Sequence[str]] = None) -> Tuple[str, List[str]]:
    """
    Take ``--executor KIND`` (before ``--ros-args``) out of the command line.

    :param args: the command line (``sys.argv`` when None)
    :return: the kind (:data:`DEFAULT_EXECUTOR` when absent) and the remaining arguments
    :raises StartupError: a missing or unknown kind
    """
    argv = list(sys.argv if args is None else args)
    end = argv.index('--ros-args') if '--ros-args' in argv else len(argv)
    kind = DEFAULT_EXECUTOR
    for index, arg in enumerate(argv[:end]):
        if arg == '--executor' or arg.startswith('--executor='):
            if '=' in arg:
                kind, used = arg.split('=', 1)[1], 1
            elif index + 1 < end:
                kind, used = argv[index + 1], 2
            else:
                raise StartupError(f'--executor: give one of {", ".join(EXECUTORS)}')
            if kind not in EXECUTORS:
                raise StartupError(f'--executor {kind}: not one of {", ".join(EXECUTORS)}')
            return kind, argv[:index] + argv[index + used:]
    return kind, argv


def spin(nodes: Sequence[Node], *, executor=DEFAULT_EXECUTOR, context=None,
         until: Optional[Callable[[], bool]] = None, duration_s: Optional[float] = None,
         period_s: float = 0.1) -> None:
    """
    Spin nodes until shutdown (SIGINT, SIGTERM), ``until()`` is true or ``duration_s`` passed.

    The one spin loop of every executable.  A signal ends it quietly: rclpy
    shuts the context down (the next wait may then fail with an RCLError, or
    raise ExternalShutdownException or KeyboardInterrupt), which is a
    shutdown, not an error.  The nodes stay alive: :func:`close` destroys them.

    :param nodes: the nodes, all of ``context``
    :param executor: an executor kind of :data:`EXECUTORS`, or an executor
    :param context: the nodes' context; None for the default one
    :param until: checked after every callback (at least every ``period_s``); True ends the loop
    :param duration_s: stop after this long [s]; None: no limit
    :param period_s: longest wait between two checks [s]
    """
    context = context or rclpy.get_default_context()
    owned = isinstance(executor, str)
    if owned:
        executor = make_executor(executor, context=context)
    for node in nodes:
        executor.add_node(node)
    deadline = None if duration_s is None else time.monotonic() + duration_s
    try:
        while context.ok() and not (until is not None and until()):
            timeout = period_s
            if deadline is not None:
                timeout = min(timeout, deadline - time.monotonic())
                if timeout <= 0:
                    break
            executor.spin_once(timeout_sec=timeout)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except _rclpy.RCLError:
        # SIGINT/SIGTERM between two waits: the signal handler shut the context down and
        # the next wait set fails to build. That is a shutdown, not an error.
        if context.ok():
            raise
    finally:
        if owned:
            executor.shutdown(timeout_sec=1.0)
        else:
            for node in nodes:
                executor.remove_node(node)


def close(nodes: Iterable[Optional[Node]], *, context=None) -> None:
    """
    Destroy the nodes (newest first) and shut the context down; safe after a signal.

    :param nodes: the nodes (None entries are skipped: a node that failed to start)
    :param context: their context; None for the default one
    """
    try:
        for node in reversed([node for node in nodes if node is not None]):
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)


def run_node(node_factory: Callable[..., Node], args: Optional[List[str]] = None) -> int:
    """
    Run one node: init, construct, check the params files, spin until shutdown, clean up.

    ``--executor events|single|multi`` before ``--ros-args`` picks the executor
    (default :data:`DEFAULT_EXECUTOR`).

    :param node_factory: the node class (called after ``rclpy.init``); start-up errors are
        logged under its node name (``FuserNode`` -> ``fuser``, remappings applied)
    :param args: command-line arguments (``--ros-args ...``); None for ``sys.argv``
    :return: exit status: 0, or 1 when the node could not start (bad parameter, calibration
        or params file, unknown executor)
    """
    name = logger_name(_default_node_name(node_factory), args)
    try:
        executor, args = split_executor_option(args)
    except StartupError as err:
        rclpy.logging.get_logger(name).fatal(f'cannot start: {err}')
        return 1
    if not init_context(args, name=name):
        return 1
    node = None
    try:
        try:
            node = node_factory()
        except STARTUP_ERRORS as err:
            rclpy.logging.get_logger(name).fatal(f'cannot start: {one_line(err)}')
            return 1
        check_params_files([node], args)
        spin([node], executor=executor)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        close([node])
    return 0


# -- params files ---------------------------------------------------------------------------------

def params_files(args: Optional[Sequence[str]] = None) -> List[str]:
    """Return the files given with ``--params-file`` after ``--ros-args`` (in order)."""
    argv = list(sys.argv if args is None else args)
    files, in_ros_args = [], False
    for flag, value in zip(argv, argv[1:] + ['']):
        if flag == '--ros-args':
            in_ros_args = True
        elif flag == '--':
            in_ros_args = False
        elif in_ros_args and flag == '--params-file' and value:
            files.append(value)
    return files


def _section_pattern(key: str) -> 're.Pattern':
    """Return the regex of a params-file node key (``/**/fuser``, ``ns/*``) over node FQNs."""
    parts = []
    for token in key.strip('/').split('/'):
        if token == '**':
            parts.append('(?:/[^/]+)*')
        elif token == '*':
            parts.append('/[^/]+')
        else:
            parts.append('/' + re.escape(token))
    return re.compile(''.join(parts) or '/')


def _flatten(values: dict, prefix: str = '') -> List[str]:
    """Return the parameter names of a ``ros__parameters`` mapping (nested keys joined by .)."""
    names = []
    for key, value in values.items():
        name = f'{prefix}{key}'
        if isinstance(value, dict):
            names.extend(_flatten(value, name + '.'))
        else:
            names.append(name)
    return names


def _load_sections(path: str) -> Dict[str, List[str]]:
    """Return node key -> parameter names of a params file ({} when rcl would refuse it)."""
    try:
        with open(path, encoding='utf-8') as stream:
            data = yaml.safe_load(stream)
    except (OSError, UnicodeDecodeError, yaml.YAMLError, RecursionError):
        return {}  # rcl reported it already (init_context)
    if not isinstance(data, dict):
        return {}
    sections = {}
    for key, section in data.items():
        parameters = section.get('ros__parameters') if isinstance(section, dict) else None
        sections[str(key)] = _flatten(parameters) if isinstance(parameters, dict) else []
    return sections


def _nearest(name: str, known: Iterable[str]) -> str:
    match = difflib.get_close_matches(name, sorted(set(known)), n=1, cutoff=0.6)
    return f' (did you mean {match[0]!r}?)' if match else ''


def check_params_files(nodes: Sequence[Node], args: Optional[Sequence[str]] = None,
                       files: Optional[Sequence[str]] = None) -> List[str]:
    """
    Warn about params-file keys no node of this process uses: one line each, nearest name.

    rcl applies a section to every node its key matches (``/**/fuser``,
    ``/camera1/detector``, ``/**``) and ignores keys a node does not
    declare.  Warned: a parameter that no matching node declares; a section
    that matches no node when its name is close to one of the nodes' (a
    misspelt node name); and a file of which no section matches any node.

    :param nodes: the process's nodes, after they declared their parameters
    :param args: the command line with ``--ros-args --params-file F`` (``sys.argv`` when None)
    :param files: the params files (default: those in ``args``)
    :return: the warnings (also logged through the first node's logger)
    """
    if not nodes:
        return []
    files = params_files(args) if files is None else list(files)
    names = {node.get_fully_qualified_name(): node for node in nodes}
    warnings = []
    for path in files:
        sections = _load_sections(path)
        matched_any = False
        for key, parameters in sections.items():
            pattern = _section_pattern(key)
            matching = [node for fqn, node in names.items() if pattern.fullmatch(fqn)]
            if not matching:
                short = {node.get_name() for node in nodes}
                hint = _nearest(key.strip('/').split('/')[-1], short)
                if hint:
                    warnings.append(f'params file {path}: section {key!r} matches no node '
                                    f'here (nodes: {", ".join(sorted(names))}){hint}; its '
                                    f'parameters are not used')
                continue
            matched_any = True
            for parameter in parameters:
                if parameter.startswith('qos_overrides.') or any(
                        node.has_parameter(parameter) for node in matching):
                    continue
                known = {p for node in matching for p in node.get_parameters_by_prefix('')}
                warnings.append(f'params file {path}: section {key!r}: unknown parameter '
                                f'{parameter!r}{_nearest(parameter, known)}; not used')
        if sections and not matched_any:
            warnings.append(f'params file {path}: no section matches '
                            f'{", ".join(sorted(names))} (sections: '
                            f'{", ".join(sections)}); running on defaults')
    logger = nodes[0].get_logger()
    for warning in warnings:
        logger.warning(warning)
    return warnings


# -- the ROS graph --------------------------------------------------------------------------------

class PublisherWatch:
    """
    Warn when another publisher appears on the topic of one of ours (two fusers, say).

    Checks the graph every ``period_s`` (rclpy has no graph-change callback);
    warns once each time the number of other publishers rises, naming their
    nodes, and logs when it is back to none.

    :param node: the node owning ``publisher``
    :param publisher: our publisher
    :param consequence: what the duplicate does, for the warning
    :param period_s: check period [s]
    """

    def __init__(self, node: Node, publisher, consequence: str, *, period_s: float = 1.0):
        self._node = node
        self._topic = publisher.topic_name
        self._consequence = consequence
        #: Publishers of the topic other than ours, at the last check.
        self.others = 0
        self._timer = node.create_timer(period_s, self.check)

    def check(self) -> int:
        """Check the graph now; return the number of other publishers."""
        infos = self._node.get_publishers_info_by_topic(self._topic)
        others = max(len(infos) - 1, 0)
        if others > self.others:
            nodes = ', '.join(sorted(
                f'{info.node_namespace.rstrip("/")}/{info.node_name}' for info in infos))
            self._node.get_logger().warning(
                f'{self._topic} has {len(infos)} publishers ({nodes}): {self._consequence}')
        elif others == 0 and self.others:
            self._node.get_logger().info(f'{self._topic}: the other publisher is gone')
        self.others = others
        return others
