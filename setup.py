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

from glob import glob
from os.path import isfile

from setuptools import find_packages, setup

package_name = 'pseudo_stereo_ros'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        # Files only: install_data cannot copy a directory (config/rig has its own entry).
        ('share/' + package_name + '/config', [f for f in glob('config/*') if isfile(f)]),
        ('share/' + package_name + '/config/rig', glob('config/rig/*')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='pseudo_stereo_ros maintainers',
    maintainer_email='maintainers@pseudo-stereo-ros.invalid',
    description='3D ball position from unsynchronized cameras at every shutter event.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'pseudo_stereo = pseudo_stereo_ros.cli.main:main',
            'detector = pseudo_stereo_ros.ros.detector_node:main',
            'fuser = pseudo_stereo_ros.ros.fuser_node:main',
            'virtual_camera = pseudo_stereo_ros.ros.virtual_camera_node:main',
            'monitor = pseudo_stereo_ros.ros.monitor_node:main',
            'camera_detector = pseudo_stereo_ros.ros.camera_detector_node:main',
            'bringup = pseudo_stereo_ros.ros.bringup:main',
            'bench_pipeline = pseudo_stereo_ros.ros.bench_pipeline:main',
            'replay = pseudo_stereo_ros.ros.replay_node:main',
            'record = pseudo_stereo_ros.ros.record_node:main',
        ],
    },
)
