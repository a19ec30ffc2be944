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
Shared glue of the package's nodes: parameter declaration and the Jazzy ``main()`` pattern.

A node's ``__init__`` raises :class:`StartupError` (or a
:class:`~pseudo_stereo_ros.calibration.CalibrationError`, or rclpy's
parameter exceptions, or rclpy's name validation) for a bad parameter or
file; :func:`run_node` logs the message, which names the parameter, as one
FATAL line and returns exit status 1.  A params file that is missing or that
rcl cannot parse (``--ros-args --params-file F``), or another bad ROS
argument, is reported the same way by :func:`init_context`, before
``rclpy.init`` and without rcl's own error line.
"""

import os
import re
import sys
from typing import Callable, List, Optional, Sequence

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
import rclpy
from rclpy.exceptions import (InvalidParameterTypeException, InvalidParameterValueException,
                              NameValidationException, ParameterException,
                              ParameterUninitializedException)
from rclpy.executors import ExternalShutdownException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
import rclpy.logging
from rclpy.node import Node
import rclpy.utilities

from ..camera import Camera
from ..errors import CalibrationError, RigError, StartupError
from ..rig import check_camera_name, config_dir, Rig

__all__ = [
    'StartupError',
    'check_camera_names',
    'declare',
    'init_context',
    'load_cameras',
    'logger_name',
    'one_line',
    'run_node',
]

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


def run_node(node_factory: Callable[..., Node], args: Optional[List[str]] = None) -> int:
    """
    Run one node: init, construct, spin until shutdown, clean up.

    :param node_factory: the node class (called after ``rclpy.init``); start-up errors are
        logged under its node name (``FuserNode`` -> ``fuser``, remappings applied)
    :param args: command-line arguments (``--ros-args ...``); None for ``sys.argv``
    :return: exit status: 0, or 1 when the node could not start (bad parameter, calibration
        or params file)
    """
    name = logger_name(_default_node_name(node_factory), args)
    if not init_context(args, name=name):
        return 1
    node = None
    try:
        try:
            node = node_factory()
        except STARTUP_ERRORS as err:
            rclpy.logging.get_logger(name).fatal(f'cannot start: {one_line(err)}')
            return 1
        try:
            rclpy.spin(node)
        except _rclpy.RCLError:
            # SIGINT/SIGTERM between two waits: the signal handler shut the context down and
            # the next wait set fails to build. That is a shutdown, not an error.
            if rclpy.ok():
                raise
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
