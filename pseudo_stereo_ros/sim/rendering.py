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
Synthetic camera frames: a ball of known radius seen by a calibrated camera.

The ball is rendered exactly, not as a disc drawn at the projected centre:
every pixel is supersampled, each sample is undistorted to a viewing ray and
is inside the ball when the ray passes within the ball's angular radius of
its centre.  Coverage (the fraction of samples inside) blends the ball's
colour over the background, so edges are anti-aliased and the image
follows the lens distortion of the calibration.  Pixel ``(i, j)`` covers
``[i - 0.5, i + 0.5] x [j - 0.5, j + 0.5]`` (OpenCV's and ROS's convention).
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from ..camera import Camera

__all__ = ['BallRenderer', 'DEFAULT_BALL_RADIUS_M', 'DEFAULT_BALL_RGB']

#: A table-tennis ball: 40 mm diameter.
DEFAULT_BALL_RADIUS_M = 0.02
#: Orange, (R, G, B).
DEFAULT_BALL_RGB = (255, 120, 0)

# Noise frames kept per renderer; frames cycle through them with a seeded random order and shift.
_NOISE_FRAMES = 4


class BallRenderer:
    """
    Render bgr8 frames of one camera with a ball at given world positions.

    :param camera: the calibrated camera (its image size and distortion are used)
    :param radius_m: ball radius [m]
    :param ball_rgb: ball colour (R, G, B), 0..255
    :param texture: ``True`` for a low-saturation textured background, ``False`` for flat grey
    :param noise_std: standard deviation of additive pixel noise [grey levels]; 0 disables
    :param supersample: samples per pixel along each axis (anti-aliasing quality)
    :param seed: random seed of the background and the noise
    """

    def __init__(self, camera: Camera, *, radius_m: float = DEFAULT_BALL_RADIUS_M,
                 ball_rgb: Sequence[int] = DEFAULT_BALL_RGB, texture: bool = True,
                 noise_std: float = 0.0, supersample: int = 4, seed: int = 0) -> None:
        if not radius_m > 0:
            raise ValueError(f'radius_m must be positive, got {radius_m}')
        if int(supersample) < 1:
            raise ValueError(f'supersample must be >= 1, got {supersample}')
        if not noise_std >= 0:
            raise ValueError(f'noise_std must be >= 0, got {noise_std}')
        self.camera = camera
        self.radius_m = float(radius_m)
        self.ball_bgr = np.array(ball_rgb[::-1], dtype=np.float32)
        self.supersample = int(supersample)
        self._rng = np.random.default_rng(seed)
        self._distorted = bool(np.any(camera.D != 0))
        width, height = camera.image_size
        self.background = self._background(width, height, texture)
        # (positive, negative) parts of the noise frames, (_NOISE_FRAMES, H, W, 3) uint8 each
        self._noise: tuple[np.ndarray, np.ndarray] | None = None
        if noise_std > 0:
            shape = (_NOISE_FRAMES, height, width, 3)
            noise = self._rng.normal(0.0, noise_std, shape)
            noise = np.clip(np.round(noise), -255, 255)
            # Saturating adds of the positive and negative parts: cheap per frame.
            self._noise = (np.clip(noise, 0, 255).astype(np.uint8),
                           np.clip(-noise, 0, 255).astype(np.uint8))
        offsets = np.arange(self.supersample) + 0.5
        self._offsets = offsets / self.supersample - 0.5  # sample positions within a pixel

    def _background(self, width: int, height: int, texture: bool) -> np.ndarray:
        if not texture:
            return np.full((height, width, 3), 110, dtype=np.uint8)
        # Smooth blotches plus fine grain, nearly grey: texture that a colour detector must ignore.
        coarse = self._rng.uniform(70, 170, (height // 40 + 2, width // 40 + 2, 1))
        smooth = cv2.resize(coarse.astype(np.float32), (width, height),
                            interpolation=cv2.INTER_CUBIC)[:, :, None]
        tint = self._rng.uniform(-8, 8, (1, 1, 3))
        grain = self._rng.normal(0, 6, (height, width, 1))
        stripes = 12 * np.sin(np.arange(width) / 9.0)[None, :, None]
        image = smooth + tint + grain + stripes
        return np.clip(np.round(image), 0, 255).astype(np.uint8)

    def ball_center_px(self, position: Sequence[float] | np.ndarray) -> np.ndarray:
        """Return the (2,) raw pixel of the ball centre (NaN behind the camera)."""
        return self.camera.project(np.asarray(position, dtype=float).reshape(1, 3))[0]

    def coverage(self, position: Sequence[float] | np.ndarray) -> tuple[int, int, np.ndarray]:
        """
        Return the fraction of each pixel covered by the ball near its image.

        :param position: ball centre (3,) in the world [m]
        :return: ``(x0, y0, patch)``: ``patch`` (h, w) float32 coverage in [0, 1] of the pixels
            ``x0 .. x0 + w - 1``, ``y0 .. y0 + h - 1``; ``patch`` is empty when nothing is seen
        """
        camera = self.camera
        width, height = camera.image_size
        empty = (0, 0, np.zeros((0, 0), dtype=np.float32))
        center_cam = camera.world_to_camera(np.asarray(position, dtype=float))[0]
        distance = float(np.linalg.norm(center_cam))
        if not center_cam[2] > self.radius_m or distance <= self.radius_m:
            return empty
        cos_alpha2 = 1.0 - (self.radius_m / distance) ** 2  # cos^2 of the angular radius
        center_px = self.ball_center_px(position)
        if not np.all(np.isfinite(center_px)):
            return empty
        # Generous box: the angular radius in pixels, grown for distortion and perspective.
        radius_px = float(camera.K[0, 0]) * self.radius_m / center_cam[2]
        half = int(np.ceil(2.0 * radius_px + 3))
        x0, y0 = int(np.floor(center_px[0])) - half, int(np.floor(center_px[1])) - half
        x1, y1 = x0 + 2 * half + 2, y0 + 2 * half + 2
        x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, width), min(y1, height)
        if x0 >= x1 or y0 >= y1:
            return empty
        step = self._offsets
        xs = (np.arange(x0, x1)[:, None] + step[None, :]).ravel()
        ys = (np.arange(y0, y1)[:, None] + step[None, :]).ravel()
        grid_x, grid_y = np.meshgrid(xs, ys)
        pixels = np.column_stack((grid_x.ravel(), grid_y.ravel()))
        if self._distorted:
            normalized = camera.normalize(pixels)
        else:
            normalized = camera.ideal_to_normalized(pixels)
        dot = normalized @ center_cam[:2] + center_cam[2]
        norm2 = np.einsum('ij,ij->i', normalized, normalized) + 1.0
        inside = (dot > 0) & (dot * dot >= cos_alpha2 * norm2 * distance * distance)
        s = self.supersample
        h, w = y1 - y0, x1 - x0
        patch = inside.reshape(h, s, w, s).mean(axis=(1, 3), dtype=np.float32)
        return x0, y0, patch

    def render(self, position: Sequence[float] | np.ndarray | None) -> np.ndarray:
        """
        Render one frame.

        :param position: ball centre (3,) in the world [m], or None for a frame without a ball
        :return: (H, W, 3) uint8 BGR image
        """
        image = self.background.copy()
        if position is not None and np.all(np.isfinite(position)):
            x0, y0, patch = self.coverage(position)
            if patch.size and patch.max() > 0:
                h, w = patch.shape
                region = image[y0:y0 + h, x0:x0 + w].astype(np.float32)
                alpha = patch[:, :, None]
                region = region * (1.0 - alpha) + self.ball_bgr * alpha
                image[y0:y0 + h, x0:x0 + w] = np.round(region).astype(np.uint8)
        if self._noise is not None:
            index = int(self._rng.integers(_NOISE_FRAMES))
            cv2.add(image, self._noise[0][index], dst=image)
            cv2.subtract(image, self._noise[1][index], dst=image)
        return image
