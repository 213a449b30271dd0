"""Grouplet texture synthesis along a flow, and fluid-driven dynamic textures (Peyré 2008).

The method class holds the parameters; what ``fit`` learns is a
:class:`texsyn.models.grouplets.GroupletModel` (the geometric layer and the marginals of the
wavelet-grouplet coefficients, section 3.1). Static synthesis (Table 1) runs the
alternating-projections driver :func:`texsyn.drivers.alternating.alternate_projections` from
white noise along the requested flow. Dynamic synthesis (Table 2) moves the flow with Stam's
stable fluids (:mod:`texsyn.ops.fluid`), carries the texture with it, and pulls every frame
back onto the grouplet model of the current flow with the same driver.

References
----------
G. Peyré, "Dynamic texture synthesis with grouplets", MAPMO workshop 2008, sections 2-4,
Tables 1-2. The steps mapped to the code, the parameters and the deviations from the paper:
``docs/methods/grouplets.md``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Annotated

import numpy as np
from scipy.ndimage import gaussian_filter

from .._validation import OneOf, Range, check_output_shape, normalize_rng
from ..drivers.alternating import alternate_projections
from ..errors import InputError
from ..models.grouplets import GroupletModel, HistogramTargets
from ..ops.flow import builtin_flow
from ..ops.fluid import advect, diffuse, project, rescale_speed
from ..ops.linalg import fixed_order
from ..ops.progress import Reporter
from ._base import Progress, TextureSynthesizer
from ._memory import output_bytes, pixel_count, shape_dims

__all__ = ["Frame", "Grouplets", "GroupletModel"]


@dataclass(frozen=True)
class Frame:
    """One frame of a dynamic texture.

    Attributes
    ----------
    index : int
    image : ndarray of float32, shape (H, W) or (H, W, 3), values in [0, 1]
    flow : ndarray of float64, shape (H, W, 2)
        The divergence-free velocity ``V_i`` that shaped it (pixels per time unit).
    """

    index: int
    image: np.ndarray
    flow: np.ndarray


class Grouplets(TextureSynthesizer):
    """Peyré's grouplet synthesis of oriented textures, static or fluid-driven (Peyré 2008).

    Parameters
    ----------
    flow : str
        Geometry of the output: 'learned' (the exemplar's direction field, tiled), 'vortex',
        'constant:ANGLE' (degrees), 'sources' or 'waves'. Any ``(H, W, 2)`` array can be used
        through :meth:`synthesize_along`.
    n_iterations : int
        Alternating projections of a static synthesis (Table 1).
    levels : int
        Detail bands ``J`` of the Laplacian tight frame (atom widths 1 ... 2^J).
    grouplet_levels : int
        Grouplet scales ``L`` (atom lengths 1 ... 2^(L-1)).
    sigma : float
        Structure-tensor smoothing in pixels (the paper uses 5).
    presmooth : float
        Gaussian pre-smoothing of the gradient in pixels.
    colour : str
        'pca': the three principal colour axes share one geometry; 'grey': grey output.
    tau : float
        Time step of the dynamic synthesis.
    viscosity : float
        Fluid viscosity ``nu`` (pixels^2 per time unit, 5-point Laplacian).
    texture_viscosity : float
        Diffusion of the advected texture (``nu~``; the paper's tour uses ``2 nu``).
    speed : float
        Root-mean-square speed of the initial flow, pixels per time unit.
    initial_flow : str
        'learned' (projected exemplar geometry) or 'noise' (projected smoothed white noise).
    n_projections : int
        Projection iterations onto the grouplet model per frame (Table 2, "a few").
    keep_speed : bool
        Rescale the flow to ``speed`` after every step (compensates viscous decay).

    Examples
    --------
    >>> import numpy as np
    >>> rows, cols = np.mgrid[:16, :16]
    >>> stripes = 0.5 + 0.5 * np.sin(0.8 * (rows + 0.3 * cols))
    >>> method = Grouplets(n_iterations=2, levels=2, grouplet_levels=2).fit(stripes)
    >>> method.sample((24, 20), rng=0).shape
    (24, 20)
    >>> [frame.image.shape for frame in method.animate(2, rng=0)]
    [(16, 16), (16, 16)]
    """

    name = "grouplets"
    summary = "Grouplet synthesis of oriented textures along a flow; fluid-driven animation (texsyn animate)"
    reference = "G. Peyré, Dynamic Texture Synthesis with Grouplets, MAPMO workshop 2008"
    has_source_map = False

    def __init__(
        self,
        *,
        flow: str = "learned",
        n_iterations: Annotated[int, Range(1, 500)] = 20,
        levels: Annotated[int, Range(1, 8)] = 3,
        grouplet_levels: Annotated[int, Range(0, 8)] = 4,
        sigma: Annotated[float, Range(0.5, 50.0)] = 5.0,
        presmooth: Annotated[float, Range(0.0, 10.0)] = 1.0,
        colour: Annotated[str, OneOf(("pca", "grey"))] = "pca",
        tau: Annotated[float, Range(0.0, 10.0, low_open=True)] = 0.5,
        viscosity: Annotated[float, Range(0.0, 100.0)] = 0.025,
        texture_viscosity: Annotated[float, Range(0.0, 100.0)] = 0.05,
        speed: Annotated[float, Range(0.0, 100.0)] = 1.0,
        initial_flow: Annotated[str, OneOf(("learned", "noise"))] = "learned",
        n_projections: Annotated[int, Range(0, 100)] = 2,
        keep_speed: bool = False,
    ):
        self.flow = flow
        self.n_iterations = n_iterations
        self.levels = levels
        self.grouplet_levels = grouplet_levels
        self.sigma = sigma
        self.presmooth = presmooth
        self.colour = colour
        self.tau = tau
        self.viscosity = viscosity
        self.texture_viscosity = texture_viscosity
        self.speed = speed
        self.initial_flow = initial_flow
        self.n_projections = n_projections
        self.keep_speed = keep_speed

    def min_exemplar_size(self) -> tuple[int, str]:
        return 8, "the structure tensor and the pyramid need at least 8x8 pixels"

    # ------------------------------------------------------------------ memory
    def _bands(self, c: int) -> int:
        """Coefficient planes per pixel: ``(levels + 1) (grouplet_levels + 1)`` per channel."""
        channels = 3 if c == 3 and self.colour == "pca" else 1
        return (self.levels + 1) * (self.grouplet_levels + 1) * channels

    def memory_terms(self, exemplar_shape, output_shape=None) -> dict[str, float]:
        """Sorted wavelet-grouplet coefficients; the output's coefficients, targets and fields.

        The redundant transform has ``(levels + 1)(grouplet_levels + 1)`` planes per channel;
        a projection holds about four copies of them besides the histogram targets of the
        output size (``docs/memory.md``).
        """
        h, w, c = shape_dims(exemplar_shape)
        k = float(h * w)
        bands = self._bands(c)
        depth = self.grouplet_levels
        terms = {"exemplar and its sorted coefficients": 8.0 * bands * k + 40.0 * k * c}
        if output_shape is None:
            terms["analysis of the exemplar"] = 12.0 * bands * k + 20.0 * depth * k + 100.0 * k + 24.0 * k * c
            return terms
        pixels = pixel_count(output_shape)
        terms["histogram targets"] = 8.0 * bands * pixels + 8.0 * c * pixels
        terms["coefficients of one projection"] = 24.0 * bands * pixels
        terms["association fields and flow"] = 40.0 * depth * pixels + 120.0 * pixels
        terms["output image"] = 8.0 * c * pixels + output_bytes(c, output_shape)
        return terms

    def _animate_terms(self, exemplar_shape, shape, loop: int) -> dict[str, float]:
        """:meth:`memory_terms` of a frame plus the fluid fields and the frames a loop keeps."""
        _, _, c = shape_dims(exemplar_shape)
        terms = self.memory_terms(exemplar_shape, shape)
        pixels = pixel_count(shape)
        terms["velocity, advection and diffusion"] = 160.0 * pixels + 24.0 * c * pixels
        if loop:
            terms["frames kept for the loop"] = loop * pixels * (4.0 * c + 16.0)
        return terms

    # ------------------------------------------------------------------ fit
    def _fit(self, exemplar: np.ndarray) -> None:
        if self.flow != "learned":
            builtin_flow(self.flow, (4, 4))  # reject unknown names before the work
        self.model_ = GroupletModel.from_exemplar(
            exemplar,
            levels=self.levels,
            grouplet_levels=self.grouplet_levels,
            sigma=self.sigma,
            presmooth=self.presmooth,
            colour=self.colour,
        )

    def flow_field(self, shape: tuple[int, int]) -> np.ndarray:
        """The raw flow of the ``flow`` parameter at an output size (the learned one is tiled)."""
        model: GroupletModel = self.model_
        if self.flow == "learned":
            h, w = shape
            rows = np.arange(h) % model.shape[0]
            cols = np.arange(w) % model.shape[1]
            return model.flow[np.ix_(rows, cols)]
        return builtin_flow(self.flow, shape)

    # ------------------------------------------------------------------ static synthesis
    def _project(
        self,
        channels: np.ndarray,
        flow: np.ndarray,
        n_iterations: int,
        targets: HistogramTargets,
        reporter: Reporter | None = None,
        preview: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> np.ndarray:
        """``S(f; Gamma, D_0)``: Table 1 passes along ``flow``, through the alternating driver."""
        model: GroupletModel = self.model_
        transform = model.transform(flow)
        return alternate_projections(
            channels,
            lambda f, _k: model.project_once(f, transform, targets),
            n_iterations,
            reporter=reporter,
            preview=preview,
        )

    def _sample(self, shape, rng, callback):
        return self._along(self.flow_field(shape), rng, callback), None

    @fixed_order
    def synthesize_along(
        self,
        flow: np.ndarray,
        *,
        rng: None | int | np.random.Generator = None,
        callback: Callable[[Progress], None] | None = None,
    ) -> np.ndarray:
        """Static synthesis along a user-given flow (paper Fig. 2): the output has the flow's size.

        Parameters
        ----------
        flow : ndarray, shape (H, W, 2)
            Raw ``(row, col)`` vectors; only their direction matters, zeros are stagnation points.
        """
        ex = self._require_fitted()
        flow = np.asarray(flow, dtype=np.float64)
        if flow.ndim != 3 or flow.shape[2] != 2:
            raise InputError(f"flow must have shape (H, W, 2), got {flow.shape}")
        size = check_output_shape(flow.shape[:2], name="flow shape")
        self._check_memory(
            ex.shape, size, task=f"synthesising along a {size[1]}x{size[0]} flow", advice="use a smaller flow"
        )
        return self._as_output(self._along(flow, normalize_rng(rng), callback))

    def _along(self, flow, rng, callback):
        """Table 1 from white noise along a raw flow; ``iteration`` records with the iterate."""
        model: GroupletModel = self.model_
        h, w = flow.shape[:2]
        reporter = Reporter(callback, "iteration", self.n_iterations)
        noise = model.noise((h, w), rng)
        channels = self._project(
            noise, flow, self.n_iterations, model.targets(h * w), reporter, model.to_image
        )
        return model.to_image(channels)

    # ------------------------------------------------------------------ dynamic synthesis
    def initial_velocity(self, shape: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
        """``V_0``: the projected learned flow, or projected smoothed noise, at RMS ``speed``.

        The paper leaves the initial flow open (``docs/methods/grouplets.md``, "Deviations").
        """
        if self.initial_flow == "learned":
            raw = self.flow_field(shape)
        else:
            width = 0.3 * min(shape)
            raw = np.stack(
                [gaussian_filter(rng.standard_normal(shape), width, mode="wrap") for _ in range(2)], axis=-1
            )
        return rescale_speed(project(raw), self.speed)

    @fixed_order
    def animate(
        self,
        n_frames: int = 60,
        shape: tuple[int, int] | None = None,
        *,
        rng: None | int | np.random.Generator = None,
        callback: Callable[[Progress], None] | None = None,
        loop: int = 0,
    ) -> Iterator[Frame]:
        """Frames of a fluid-driven dynamic texture (paper Table 2 with Stam's stable fluids).

        Frame 0 is a static synthesis along ``V_0``; every next frame advects the flow and the
        texture by the flow (semi-Lagrangian), diffuses both implicitly (``viscosity``,
        ``texture_viscosity``), projects the flow to be divergence-free, and pulls the texture
        back onto the grouplet model of the new flow with ``n_projections`` iterations.

        Parameters
        ----------
        n_frames : int
            Number of frames, frame 0 included.
        shape : (int, int), optional
            Frame size; the exemplar's by default.
        loop : int
            When positive, the sequence loops seamlessly: ``n_frames + loop`` frames are
            simulated, the first ``loop`` ones are cross-faded into the last ``loop`` ones, and
            the sequence starts at simulated frame ``loop`` (its last frame leads back to its
            first). Not in the paper.

        Yields
        ------
        Frame
        """
        ex = self._require_fitted()
        shape = tuple(ex.shape[:2]) if shape is None else check_output_shape(shape)
        overlap = int(loop) if loop else 0
        self._check_memory(
            ex.shape,
            shape,
            task=f"animating {shape[1]}x{shape[0]} frames",
            advice="request smaller frames" + (" or a shorter loop" if loop else ""),
            terms=self._animate_terms(ex.shape, shape, overlap),
        )
        if overlap and not 0 < overlap < int(n_frames):
            raise InputError(f"loop must be between 1 and n_frames - 1 = {int(n_frames) - 1}, got {overlap}")
        if int(n_frames) < 1:
            raise InputError(f"n_frames must be at least 1, got {n_frames}")
        frames = self._simulate(int(n_frames) + overlap, shape, normalize_rng(rng), callback)
        yield from _crossfade(frames, int(n_frames), overlap) if overlap else frames

    def _simulate(self, n_frames: int, shape, rng: np.random.Generator, callback) -> Iterator[Frame]:
        """Table 2: frame 0 along ``V_0``, then advect, diffuse, project and re-project."""
        model: GroupletModel = self.model_
        reporter = Reporter(callback, "frames", n_frames)
        targets = model.targets(shape[0] * shape[1])
        velocity = self.initial_velocity(shape, rng)
        first = reporter.stage_of("first frame", self.n_iterations)
        texture = self._project(model.noise(shape, rng), velocity, self.n_iterations, targets, first)
        for index in range(n_frames):
            if index > 0:
                texture = advect(texture, velocity, self.tau)  # step 2, with the old velocity
                moved = advect(velocity, velocity, self.tau)
                texture = diffuse(texture, self.tau * self.texture_viscosity)  # step 3
                velocity = project(diffuse(moved, self.tau * self.viscosity))  # step 4
                if self.keep_speed:
                    velocity = rescale_speed(velocity, self.speed)
                texture = self._project(texture, velocity, self.n_projections, targets)
            reporter(index + 1)
            yield Frame(index, self._as_output(model.to_image(texture)), velocity.copy())


def _crossfade(frames: Iterable[Frame], n_frames: int, overlap: int) -> Iterator[Frame]:
    """A looping sequence: drop the first ``overlap`` frames and fade the last ones into them."""
    head = []
    for frame in frames:
        i = frame.index
        if i < overlap:
            head.append(frame)
        elif i < n_frames:
            yield Frame(i - overlap, frame.image, frame.flow)
        else:
            k = i - n_frames
            w = (k + 1) / (overlap + 1)
            image = (1 - w) * frame.image.astype(np.float64) + w * head[k].image
            flow = (1 - w) * frame.flow + w * head[k].flow
            yield Frame(i - overlap, image.astype(np.float32), flow)
