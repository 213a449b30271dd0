"""Grouplet texture synthesis along a flow, and fluid-driven dynamic textures (Peyré 2008).

The method class holds the parameters; what ``fit`` learns is a
:class:`texsyn.models.grouplets.GroupletModel` (the geometric layer and the marginals of the
wavelet-grouplet coefficients, section 3.1). Static synthesis (Table 1) runs the
alternating-projections driver :func:`texsyn.drivers.alternating.alternate_projections` from
white noise along the requested flow. Dynamic synthesis (Table 2) runs the fluid driver
(:mod:`texsyn.drivers.fluid`): the flow evolves with Stam's stable fluids and a turbulent
forcing, the texture is carried by it in renewed layers, and every frame is pulled back onto
the grouplet model of the current flow with a few passes of Table 1.

Why this module is long: one method class holds both of the paper's modes, static
synthesis (Table 1) and fluid-driven animation (Table 2), because they share the fitted
model, the projection and most parameters; the loops themselves live in the drivers.

References
----------
G. Peyré, "Dynamic texture synthesis with grouplets", MAPMO workshop 2008, sections 2-4,
Tables 1-2. The steps mapped to the code, the parameters and the deviations from the paper:
``docs/methods/grouplets.md``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Annotated

import numpy as np

from .._validation import OneOf, Range, check_output_shape, normalize_rng
from ..drivers.alternating import alternate_projections
from ..errors import InputError
from ..models.grouplets import GroupletModel, HistogramTargets
from ..ops.flow import builtin_flow, periodic_tiling
from ..ops.linalg import fixed_order
from ..ops.progress import Reporter
from ..transforms.grouplets import WaveletGroupletTransform
from ._base import Progress, TextureSynthesizer
from ._memory import output_bytes, pixel_count, shape_dims

if TYPE_CHECKING:  # the fluid modules load with the first animation, not with the method
    from ..drivers.fluid import FlowDynamics

__all__ = ["Frame", "Grouplets", "GroupletModel"]

#: how far (in e-folds of the eddies' strain, speed * 2 pi / flow_scale per frame) the flow
#: may stretch a layer of texture before it has faded out, when ``renewal`` is automatic
RENEWAL_STRAIN = 1.5

#: the shortest life of a layer: with fewer frames, a layer fades out before the flow has
#: moved it, and every frame is a fresh synthesis
MIN_RENEWAL = 4

#: integration step (pixels) of the association fields of the fluid's velocity fields: they
#: are smooth (diffused and projected), so RK4 at 1 pixel follows them as closely as the
#: static default of 0.25 (0.1 % of the associations differ at 256x256) four times faster
FLUID_ASSOCIATION_STEP = 1.0


@dataclass(frozen=True)
class Frame:
    """One frame of a dynamic texture.

    Attributes
    ----------
    index : int
    image : ndarray of float32, shape (H, W) or (H, W, 3), values in [0, 1]
    flow : ndarray of float64, shape (H, W, 2)
        The divergence-free velocity ``V_i`` that shaped it (pixels per time unit): the
        texture moves by ``tau * flow`` to the next frame.
    """

    index: int
    image: np.ndarray
    flow: np.ndarray


class Grouplets(TextureSynthesizer):
    """Peyré's grouplet synthesis of oriented textures, static or fluid-driven (Peyré 2008).

    Parameters
    ----------
    flow : str
        Geometry of the output: 'learned' (the exemplar's direction field, repeated
        periodically), 'vortex', 'constant:ANGLE' (degrees), 'sources' or 'waves'. Any
        ``(H, W, 2)`` array can be used through :meth:`synthesize_along`.
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
        Time step between frames (Table 2).
    viscosity : float
        Fluid viscosity ``nu`` (pixels^2 per time unit, 5-point Laplacian).
    texture_viscosity : float
        Diffusion ``nu~`` of the advected texture before each projection.
    speed : float
        Root-mean-square motion of the texture in pixels per frame.
    initial_flow : str
        ``V_0``: 'learned' (the exemplar's geometry), 'turbulence' (random eddies of
        ``flow_scale`` with the ``spectrum_slope`` energy spectrum), 'vortices' (Gaussian
        vortices ``flow_scale`` across: radius ``sigma = flow_scale / 4``) or 'noise'
        (smoothed white noise, round 1's).
    turbulence : float
        Random forcing that keeps the flow evolving: the fraction of the flow's speed it adds
        per frame (0: the flow only evolves by itself, and slowly).
    flow_scale : float
        Wavelength in pixels of the eddies of the 'turbulence' and 'vortices' flows and of
        the forcing; 0 picks half the smaller frame side.
    spectrum_slope : float
        Energy spectrum ``E(k) ~ k^-slope`` above the eddy scale (3: 2-D turbulence's
        enstrophy cascade; 5/3: Kolmogorov's, with more small eddies).
    n_projections : int
        Projection passes onto the grouplet model per frame (Table 2, "a few").
    keep_speed : bool
        Hold the flow at ``speed`` at every step; otherwise viscosity slows it down.
    advection : str
        How the texture follows the flow: 'layers' (renewed layers: static syntheses carried
        by the flow, each fading out after ``renewal`` frames while the next fades in, so
        the flow never stretches the material far) or 'paper' (the paper's literal loop,
        which advects the last frame forever: the material turns into long stripes).
    renewal : int
        Frames each layer lives (0, or at least :data:`MIN_RENEWAL`); 0 picks the time the eddies take to stretch the material
        by about ``RENEWAL_STRAIN`` (``RENEWAL_STRAIN * flow_scale / (2 pi speed)`` frames,
        between 8 and 240).
    layer_iterations : int
        Table 1 passes of each new layer (frame 0's layers included).

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
    #: the terms lie from 5 % below (128 -> 256 grey) to 3 % above (512 colour) the resident
    #: peaks, Numba's arrays of the association fields included; 1.2 bounds them within 25 %
    #: (``docs/memory.md``, "Second round")
    memory_margin = 1.2

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
        texture_viscosity: Annotated[float, Range(0.0, 100.0)] = 0.0,
        speed: Annotated[float, Range(0.0, 100.0)] = 1.0,
        initial_flow: Annotated[str, OneOf(("learned", "turbulence", "vortices", "noise"))] = "learned",
        turbulence: Annotated[float, Range(0.0, 10.0)] = 0.1,
        flow_scale: Annotated[float, Range(0.0, 4096.0)] = 0.0,
        spectrum_slope: Annotated[float, Range(0.0, 10.0)] = 3.0,
        n_projections: Annotated[int, Range(0, 100)] = 2,
        keep_speed: bool = True,
        advection: Annotated[str, OneOf(("layers", "paper"))] = "layers",
        renewal: Annotated[int, Range(0, 100000)] = 0,
        layer_iterations: Annotated[int, Range(1, 500)] = 10,
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
        self.turbulence = turbulence
        self.flow_scale = flow_scale
        self.spectrum_slope = spectrum_slope
        self.n_projections = n_projections
        self.keep_speed = keep_speed
        self.advection = advection
        self.renewal = renewal
        self.layer_iterations = layer_iterations

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
        # the sorted coefficients and pixels, and the exemplar's association fields (int64)
        terms = {"exemplar and its sorted coefficients": 8.0 * bands * k + 40.0 * k * c + 8.0 * depth * k}
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
        """:meth:`memory_terms` of a frame, the fluid fields, two layers, and a loop's run-up.

        A loop keeps the velocities of its ``loop`` closing frames and of the last half
        layer life (``docs/methods/grouplets.md``, "Loops").
        """
        _, _, c = shape_dims(exemplar_shape)
        terms = self.memory_terms(exemplar_shape, shape)
        pixels = pixel_count(shape)
        terms["velocity, forcing and advection"] = 160.0 * pixels + 24.0 * c * pixels
        terms["two advected layers"] = 2.0 * pixels * (8.0 * c + 16.0 + 24.0)
        if loop:
            kept = loop + max(1, self.layer_life(shape) // 2)
            terms["velocities kept for the loop"] = kept * pixels * 16.0
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
        """The raw flow of the ``flow`` parameter at an output size.

        The learned field is repeated periodically (:func:`texsyn.ops.flow.periodic_tiling`:
        tiled at multiples of the exemplar's size; otherwise tiled the nearest whole number
        of times and stretched to fit, by 3/4 to 3/2 per axis, or shrunk when the output is
        smaller than the exemplar), so the periodic synthesis has no seam.
        """
        model: GroupletModel = self.model_
        if self.flow == "learned":
            return periodic_tiling(model.flow, shape)
        return builtin_flow(self.flow, shape)

    # ------------------------------------------------------------------ static synthesis
    def _project(
        self,
        channels: np.ndarray,
        transform: WaveletGroupletTransform,
        n_iterations: int,
        targets: HistogramTargets,
        reporter: Reporter | None = None,
        preview: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> np.ndarray:
        """``S(f; Gamma, D_0)``: Table 1 passes with ``transform`` (along a flow ``Gamma``),
        through the alternating driver."""
        model: GroupletModel = self.model_
        if n_iterations == 0:
            return channels
        buffers = model.buffers(transform)
        return alternate_projections(
            channels,
            lambda f, _k: model.project_once(f, transform, targets, buffers),
            n_iterations,
            reporter=reporter,
            preview=preview,
        )

    def periodic_for(self, shape):
        """Every step is periodic (FFT pyramid and diffusion, wrapped association fields): the
        output wraps whenever its flow does, the learned one (repeated periodically,
        :meth:`flow_field`) or a constant direction (``docs/tiling.md``)."""
        return self.flow == "learned" or self.flow.strip().lower().startswith("constant")

    def _sample(self, shape, rng, callback):
        flow = self.flow_field(shape)
        # an exact tiling of the learned field reuses the exemplar's association fields
        transform = self.model_.tiled_transform(shape) if self.flow == "learned" else None
        return self._along(flow, rng, callback, transform), None

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

    def _along(self, flow, rng, callback, transform: WaveletGroupletTransform | None = None):
        """Table 1 from white noise along a raw flow; ``iteration`` records with the iterate.

        ``transform``: the transform along ``flow`` when the caller has it already
        (:meth:`GroupletModel.tiled_transform`)."""
        model: GroupletModel = self.model_
        h, w = flow.shape[:2]
        reporter = Reporter(callback, "iteration", self.n_iterations)
        noise = model.noise((h, w), rng)
        if transform is None:
            transform = model.transform(flow)
        channels = self._project(
            noise, transform, self.n_iterations, model.targets(h * w), reporter, model.to_image
        )
        return model.to_image(channels)

    # ------------------------------------------------------------------ dynamic synthesis
    def dynamics(self, shape: tuple[int, int]) -> FlowDynamics:
        """How the flow of an animation with frames of ``shape`` evolves (the parameters)."""
        from ..drivers.fluid import FlowDynamics

        return FlowDynamics(
            tau=self.tau,
            viscosity=self.viscosity,
            speed=self.speed,
            keep_speed=self.keep_speed,
            turbulence=self.turbulence,
            scale=self._flow_scale(shape),
            slope=self.spectrum_slope,
        )

    def _flow_scale(self, shape: tuple[int, int]) -> float:
        return float(self.flow_scale) if self.flow_scale > 0 else max(4.0, min(shape) / 2.0)

    def layer_life(self, shape: tuple[int, int]) -> int:
        """Frames each advected layer lives in an animation with frames of ``shape``.

        ``renewal`` when set; otherwise the frames the eddies of ``flow_scale`` take to
        stretch the material by :data:`RENEWAL_STRAIN` e-folds (their strain rate is about
        ``2 pi speed / flow_scale`` per frame), between 8 and 240.
        """
        if self.renewal > 0:
            return int(self.renewal)
        strain = 2.0 * np.pi * max(self.speed, 1e-6) / self._flow_scale(shape)
        return int(np.clip(round(RENEWAL_STRAIN / strain), 8, 240))

    def initial_velocity(self, shape: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
        """``V_0``: the ``initial_flow`` made divergence-free, moving ``speed`` pixels per frame.

        The paper leaves the initial flow open (``docs/methods/grouplets.md``, "Deviations").
        """
        from ..ops.fluid import project, rescale_speed, spectral_velocity, vortex_velocity

        scale = self._flow_scale(shape)
        if self.initial_flow == "learned":
            raw = self.flow_field(shape)
        elif self.initial_flow == "turbulence":
            raw = spectral_velocity(shape, rng, scale=scale, slope=self.spectrum_slope)
        elif self.initial_flow == "vortices":
            raw = vortex_velocity(shape, rng, scale=scale / 4.0)  # a vortex spans +-2 sigma
        else:
            from scipy.ndimage import gaussian_filter  # the 'noise' flow only (start-up)

            width = 0.3 * min(shape)
            raw = np.stack(
                [gaussian_filter(rng.standard_normal(shape), width, mode="wrap") for _ in range(2)], axis=-1
            )
        return rescale_speed(project(raw), self.speed / self.tau)

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
        """Frames of a fluid-driven dynamic texture (paper Table 2).

        The flow starts as ``initial_flow`` and evolves with Stam's stable fluids (advect,
        diffuse, project onto divergence-free fields) and the ``turbulence`` forcing, at
        ``speed`` pixels per frame. The texture moves with it: in renewed layers (static
        syntheses carried by the flow, each living :meth:`layer_life` frames), or as the
        paper's literal loop with ``advection='paper'``; every frame is projected onto the
        grouplet model of the current flow with ``n_projections`` passes of Table 1.

        Parameters
        ----------
        n_frames : int
            Number of frames, frame 0 included.
        shape : (int, int), optional
            Frame size; the exemplar's by default.
        loop : int
            When positive, the sequence is periodic: the flow is steered back onto its own
            start over the last ``loop`` frames and the texture layers are born at the same
            phases in every period, so the frame after the last one is the first one. Needs
            ``advection='layers'``.

        Yields
        ------
        Frame
        """
        ex = self._require_fitted()
        shape = tuple(ex.shape[:2]) if shape is None else check_output_shape(shape)
        closing = int(loop) if loop else 0
        self._check_memory(
            ex.shape,
            shape,
            task=f"animating {shape[1]}x{shape[0]} frames",
            advice="request smaller frames" + (" or a shorter loop" if loop else ""),
            terms=self._animate_terms(ex.shape, shape, closing),
        )
        if int(n_frames) < 1:
            raise InputError(f"n_frames must be at least 1, got {n_frames}")
        if closing and not 0 < closing < int(n_frames):
            raise InputError(f"loop must be between 1 and n_frames - 1 = {int(n_frames) - 1}, got {closing}")
        if 0 < self.renewal < MIN_RENEWAL:
            raise InputError(
                f"renewal must be 0 (automatic) or at least {MIN_RENEWAL} frames, got {self.renewal}"
                " (shorter-lived layers make every frame a new synthesis)"
            )
        if closing and self.advection == "paper":
            raise InputError(
                "loop needs advection='layers' (the paper's literal loop cannot close on itself)"
            )
        yield from self._simulate(int(n_frames), shape, normalize_rng(rng), callback, closing)

    def _simulate(
        self, n_frames: int, shape, rng: np.random.Generator, callback, closing: int
    ) -> Iterator[Frame]:
        """Table 2 through the fluid driver, with this model's synthesis and projection."""
        from ..drivers.fluid import flow_sequence, looped_flow_sequence, texture_frames

        model: GroupletModel = self.model_
        targets = model.targets(shape[0] * shape[1])
        dynamics = self.dynamics(shape)
        flow_seed = int(rng.integers(2**63))
        initial = self.initial_velocity(shape, np.random.default_rng(flow_seed))

        def velocities() -> Iterator[np.ndarray]:
            flow_rng = np.random.default_rng([flow_seed, 1])
            if closing:
                return looped_flow_sequence(initial, n_frames, closing, dynamics, flow_rng)
            return flow_sequence(initial, n_frames, dynamics, flow_rng)

        latest: list = [None, None]  # the last velocity and its transform (a birth frame uses it twice)

        def transform_along(velocity: np.ndarray) -> WaveletGroupletTransform:
            if latest[0] is not velocity:
                latest[:] = [velocity, model.transform(velocity, step=FLUID_ASSOCIATION_STEP)]
            return latest[1]

        def synthesize(velocity: np.ndarray) -> np.ndarray:
            noise = model.noise(shape, rng)
            return self._project(noise, transform_along(velocity), self.layer_iterations, targets)

        def project_texture(texture: np.ndarray, velocity: np.ndarray) -> np.ndarray:
            return self._project(texture, transform_along(velocity), self.n_projections, targets)

        frames = texture_frames(
            velocities,
            n_frames,
            synthesize=synthesize,
            project_texture=project_texture,
            mean=model.pixel_values.mean(axis=1),
            tau=self.tau,
            renewal=0 if self.advection == "paper" else self.layer_life(shape),
            texture_viscosity=self.texture_viscosity,
            loop=bool(closing),
            reporter=Reporter(callback, "frames", n_frames),
        )
        for index, (texture, velocity) in enumerate(frames):
            # a copy: the driver keeps the velocity it yields to make the next one
            yield Frame(index, self._as_output(model.to_image(texture)), velocity.copy())
