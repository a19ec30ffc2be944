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

"""``pseudo_stereo table1``: the paper's Table 1 and Fig. 6 on the default rig."""

from pathlib import Path

from .common import check_pixel_options
from ..evaluation.table1 import format_table1, plot_figure6, run_table1
from ..sim.scenarios import default_rig

NAME = 'table1'
HELP = "reproduce the paper's Table 1 (and a Fig. 6-like PNG) on the simulated default rig"


def add_arguments(parser) -> None:
    """Add this command's options."""
    parser.add_argument('--out', default='out/table1', metavar='DIR',
                        help='directory for figure6.png and table1.txt (default: %(default)s)')
    parser.add_argument('--noise', type=float, default=0.0, metavar='PX',
                        help='Gaussian pixel noise [px] (default: none, as in the paper)')
    parser.add_argument('--quantization', type=float, default=0.05, metavar='PX',
                        help='sub-pixel step of the detections [px] (default: %(default)s)')


def run(args) -> int:
    """Run the command."""
    check_pixel_options(args)
    results = run_table1(default_rig(), noise_px=args.noise, quantization_px=args.quantization)
    text = format_table1(results)
    if args.noise or args.quantization != 0.05:
        text += (f'\nDetections: Gaussian noise {args.noise} px, quantization '
                 f'{args.quantization} px (the paper: none; default quantization 0.05 px).')
    print(text)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / 'table1.txt').write_text(text + '\n', encoding='utf-8')
    plot_figure6(results, out / 'figure6.png')
    print(f'wrote {out / "table1.txt"} and {out / "figure6.png"}')
    return 0
