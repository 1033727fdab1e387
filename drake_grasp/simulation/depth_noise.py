"""A noisy depth camera: what a structured-light or stereo sensor does to a perfect rendered depth image.

Applied in this order to every pixel with a reading (z metres):
1. axial noise: Gaussian, sigma(z) = `sigma_base` + `sigma_quadratic` * z^2 (stereo and
   structured-light error grows with the square of the range; about 1.5 mm at 1.3 m with
   the defaults, as an Intel RealSense D415 at that range);
2. lost pixels at depth edges: a pixel with a 4-neighbour more than `edge_jump` nearer or
   farther (or without a reading) is dropped with probability `edge_dropout` (the shadow
   and mixed-pixel band at object silhouettes), plus `random_dropout` of all pixels;
3. quantization to `quantization` (1 mm, as a 16-bit millimetre image).
A dropped pixel, and one without a reading (too near or too far), reads 0, as a driver
reports it. The noise is a pure function of the image and the generator; `DepthNoiseSystem`
draws a generator from (seed, time in ms, its own stream), so the same seed gives the same
noisy images.
"""

# No `from __future__ import annotations`: yaml_load_typed reads the dataclass field types.
import dataclasses as dc

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem
from pydrake.systems.sensors import ImageDepth32F

NOISE_STREAM = 7  # the generator's third key: noise never shares random numbers with the sampler


@dc.dataclass
class DepthNoiseConfig:
    enabled: bool = False
    sigma_base: float = 0.0005  # [m]
    sigma_quadratic: float = 0.0006  # [1/m]: sigma grows as z^2
    edge_jump: float = 0.01  # [m] a neighbour this much nearer or farther makes a pixel an edge pixel
    edge_dropout: float = 0.5
    random_dropout: float = 0.002
    quantization: float = 0.001  # [m]


def add_depth_noise(depth: np.ndarray, config: DepthNoiseConfig, rng: np.random.Generator) -> np.ndarray:
    """A noisy copy of a depth image [m]; pixels without a reading (0, inf or NaN) stay without."""
    z = np.asarray(depth, dtype=np.float32)
    valid = np.isfinite(z) & (z > 0)
    zv = np.where(valid, z, 0.0)
    sigma = config.sigma_base + config.sigma_quadratic * zv**2
    noisy = zv + rng.normal(size=z.shape).astype(np.float32) * sigma
    padded = np.pad(np.where(valid, z, np.inf), 1, mode="edge")
    centre = padded[1:-1, 1:-1]
    jump = np.zeros(z.shape, dtype=bool)
    for dy, dx in ((0, 1), (2, 1), (1, 0), (1, 2)):
        neighbour = padded[dy:dy + z.shape[0], dx:dx + z.shape[1]]
        with np.errstate(invalid="ignore"):
            jump |= ~(np.abs(neighbour - centre) <= config.edge_jump)
    drop = jump & (rng.uniform(size=z.shape) < config.edge_dropout)
    drop |= rng.uniform(size=z.shape) < config.random_dropout
    if config.quantization > 0:
        noisy = np.round(noisy / config.quantization) * config.quantization
    return np.where(valid & ~drop, noisy, 0.0).astype(np.float32)


class DepthNoiseSystem(LeafSystem):
    """`depth_image` (ImageDepth32F) in, the same image with `add_depth_noise` out."""

    def __init__(self, config: DepthNoiseConfig, *, width: int, height: int, seed: int = 0):
        super().__init__()
        self._config, self._seed = config, seed
        blank = AbstractValue.Make(ImageDepth32F(width, height))
        self._input = self.DeclareAbstractInputPort("depth_image", blank)
        tickets = {self.all_input_ports_ticket(), self.time_ticket()}
        self.DeclareAbstractOutputPort("noisy_depth_image", blank.Clone, self._calc,
                                       prerequisites_of_calc=tickets)

    def _calc(self, context, output) -> None:
        image = self._input.Eval(context)
        # A stream of its own: the grasp selector draws from [seed, ms] with the same episode seed.
        rng = np.random.default_rng([self._seed, int(round(context.get_time() * 1000)), NOISE_STREAM])
        noisy = add_depth_noise(np.array(image.data, copy=False)[..., 0], self._config, rng)
        out = output.get_mutable_value()
        out.mutable_data[..., 0] = noisy
