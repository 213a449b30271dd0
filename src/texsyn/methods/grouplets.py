"""Grouplet texture synthesis along a flow, and fluid-driven dynamic textures (Peyré 2008).

The model has a geometric layer (a direction field learned from the exemplar's structure
tensor, or given by the user) and a coefficient layer (the marginal histograms of the
exemplar's wavelet-grouplet coefficients and of its pixels). Static synthesis (Table 1)
projects white noise alternately onto the band histograms and the pixel histogram of the
wavelet-grouplet transform built on the requested flow. Dynamic synthesis (Table 2) moves the
flow with Stam's stable fluids, advects the texture with it, and projects every frame onto the
grouplet model of the current flow.

References
----------
G. Peyré, "Dynamic texture synthesis with grouplets", MAPMO workshop 2008, sections 2-4,
Tables 1-2. Implementation notes: spec 03 (resolutions G1-G14).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Callable, Iterator

import numpy as np
from scipy.ndimage import gaussian_filter

from .._validation import OneOf, Range, check_output_shape, normalize_rng
from ..ops import ColorPCA, hist_target, luma, match_sorted_rows, periodic_smooth_decomposition
from ..ops.flow import association_fields, builtin_flow, orient_field, structure_tensor_orientation
from ..ops.fluid import advect, diffuse, project, rescale_speed
from ..ops.grouplets import WaveletGroupletTransform
from ._base import Progress, TextureSynthesizer
from ._memory import shape_dims, output_bytes, pixel_count
from ..errors import InputError
from ..ops.linalg import fixed_order

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


class GroupletModel:
    """The statistics of Peyré's grouplet model, learned from an exemplar (paper section 3.1).

    Parameters
    ----------
    exemplar : ndarray, shape (H, W) or (H, W, 3)
    levels, grouplet_levels : int
        ``J`` pyramid detail bands and ``L`` grouplet scales.
    sigma, presmooth : float
        Structure-tensor smoothing and gradient pre-smoothing (pixels).
    colour : {'pca', 'grey'}
        Colour exemplars: synthesise the three principal colour axes with one shared geometry
        (spec 00, 6.3 b), or convert to grey.

    Attributes
    ----------
    flow : ndarray (H, W, 2)
        Learned direction field ``Gamma_0`` (unit vectors, signs optimised).
    coherence : ndarray (H, W)
    band_values : ndarray (J+1, L+1, C, H*W)
        Sorted wavelet-grouplet coefficients of the exemplar's periodic component.
    pixel_values : ndarray (C, H*W)
        Sorted pixel values (principal-axis coordinates for colour).
    """

    def __init__(self, exemplar: np.ndarray, *, levels: int = 3, grouplet_levels: int = 4, sigma: float = 5.0, presmooth: float = 1.0, colour: str = "pca"):
        img = np.asarray(exemplar, dtype=np.float64)  # (H, W) or (H, W, 3)
        self.levels = int(levels)
        self.grouplet_levels = int(grouplet_levels)
        # one periodic component (Moisan) serves the geometry and the statistics: the
        # decomposition is linear and keeps the mean, so it commutes with luma and colour PCA
        periodic_img = periodic_smooth_decomposition(img)[0]
        if img.ndim == 3 and colour == "pca":
            self.pca: ColorPCA | None = ColorPCA(img)
            coords, periodic = self.pca.forward(img), self.pca.forward(periodic_img)
        else:
            self.pca = None
            coords, periodic = luma(img)[..., None], luma(periodic_img)[..., None]
        orientation, self.coherence = structure_tensor_orientation(luma(periodic_img), sigma=sigma, presmooth=presmooth)
        self.flow = orient_field(orientation)
        self.shape = img.shape[:2]
        transform = self.transform(self.flow)
        coefficients = transform.forward(periodic)  # (J+1, L+1, C, H, W)
        b = coefficients.reshape(coefficients.shape[:3] + (-1,))
        self.band_values = np.sort(b, axis=-1)
        self.pixel_values = np.sort(coords.reshape(-1, coords.shape[2]).T, axis=-1)
        self._targets: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    @property
    def channels(self) -> int:
        return self.pixel_values.shape[0]

    def transform(self, flow: np.ndarray) -> WaveletGroupletTransform:
        """The wavelet-grouplet transform along ``flow`` (raw vectors, any size)."""
        flow = np.asarray(flow, dtype=np.float64)
        return WaveletGroupletTransform(association_fields(flow, self.grouplet_levels), flow.shape[:2], self.levels)

    def targets(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Sorted target values for ``n`` pixels: bands ``(B, n)`` and pixels ``(C, n)`` (spec 00, 5.2)."""
        found = self._targets.get(n)
        if found is None:
            bands = self.band_values.reshape(-1, self.band_values.shape[-1])
            found = (
                np.stack([hist_target(n, row, presorted=True) for row in bands]),
                np.stack([hist_target(n, row, presorted=True) for row in self.pixel_values]),
            )
            self._targets[n] = found
        return found

    def noise(self, shape: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
        """White noise ``(H, W, C)`` with the exemplar's mean and deviation per channel."""
        mean = self.pixel_values.mean(axis=1)
        std = self.pixel_values.std(axis=1)
        return mean + std * rng.standard_normal(tuple(shape) + (self.channels,))

    def match_bands(self, coefficients: np.ndarray) -> np.ndarray:
        """Give every band of ``(J+1, L+1, C, H, W)`` coefficients the exemplar's histogram."""
        n = coefficients.shape[-1] * coefficients.shape[-2]
        bands, _ = self.targets(n)
        rows = coefficients.reshape(-1, n)
        return match_sorted_rows(rows, bands).reshape(coefficients.shape)

    def match_pixels(self, image: np.ndarray) -> np.ndarray:
        """Give every channel of an ``(H, W, C)`` image the exemplar's pixel histogram."""
        n = image.shape[0] * image.shape[1]
        _, pixels = self.targets(n)
        return match_sorted_rows(image.reshape(n, self.channels).T, pixels).T.reshape(image.shape)

    def project(
        self,
        image: np.ndarray,
        transform: WaveletGroupletTransform,
        iterations: int,
        callback: Callable[[int, np.ndarray], None] | None = None,
    ) -> np.ndarray:
        """Alternating projections onto the model (paper Table 1, steps 2-6, corrected as G4)."""
        f = image
        for k in range(iterations):
            f = self.match_pixels(transform.inverse(self.match_bands(transform.forward(f))))
            if callback is not None:
                callback(k + 1, f)
        return f

    def to_image(self, channels: np.ndarray) -> np.ndarray:
        """``(H, W, C)`` model channels (principal-axis coordinates) to an ``(H, W[, 3])`` image."""
        return self.pca.inverse(channels) if self.pca is not None else channels[..., 0]


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
        a projection holds about four copies of them besides the cached histogram targets
        (``docs/memory.md``).
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

    def _fit(self, exemplar: np.ndarray) -> None:
        if self.flow != "learned":
            builtin_flow(self.flow, (4, 4))  # reject unknown names before the work
        self.model_ = GroupletModel(
            exemplar,
            levels=self.levels,
            grouplet_levels=self.grouplet_levels,
            sigma=self.sigma,
            presmooth=self.presmooth,
            colour=self.colour,
        )

    # ------------------------------------------------------------------ flows
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
        model: GroupletModel = self.model_
        transform = model.transform(flow)
        def report(k, f):
            if callback is not None:
                callback(Progress("iteration", k, self.n_iterations, image=model.to_image(f)))

        channels = model.project(model.noise(flow.shape[:2], rng), transform, self.n_iterations, report)
        return model.to_image(channels)

    # ------------------------------------------------------------------ dynamic synthesis
    def initial_velocity(self, shape: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
        """``V_0``: the projected learned flow, or projected smoothed noise, at RMS ``speed`` (spec 03, 10)."""
        if self.initial_flow == "learned":
            raw = self.flow_field(shape)
        else:
            width = 0.3 * min(shape)
            raw = np.stack([gaussian_filter(rng.standard_normal(shape), width, mode="wrap") for _ in range(2)], axis=-1)
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
        self._check_memory(
            ex.shape,
            shape,
            task=f"animating {shape[1]}x{shape[0]} frames",
            advice="request smaller frames" + (" or a shorter loop" if loop else ""),
            terms=self._animate_terms(ex.shape, shape, int(loop) if loop else 0),
        )
        if loop:
            yield from self._looped(n_frames, shape, rng=rng, callback=callback, overlap=int(loop))
            return
        if int(n_frames) < 1:
            raise InputError(f"n_frames must be at least 1, got {n_frames}")
        generator = normalize_rng(rng)
        model: GroupletModel = self.model_
        velocity = self.initial_velocity(shape, generator)
        def first(k, _f):
            if callback is not None:
                callback(Progress("first frame", k, self.n_iterations))

        texture = model.project(model.noise(shape, generator), model.transform(velocity), self.n_iterations, first)
        for index in range(int(n_frames)):
            if index > 0:
                texture = advect(texture, velocity, self.tau)
                moved = advect(velocity, velocity, self.tau)
                texture = diffuse(texture, self.tau * self.texture_viscosity)
                velocity = project(diffuse(moved, self.tau * self.viscosity))
                if self.keep_speed:
                    velocity = rescale_speed(velocity, self.speed)
                texture = model.project(texture, model.transform(velocity), self.n_projections)
            if callback is not None:
                callback(Progress("frames", index + 1, int(n_frames)))
            yield Frame(index, self._as_output(model.to_image(texture)), velocity.copy())

    def _looped(self, n_frames, shape, *, rng, callback, overlap):
        if not 0 < overlap < int(n_frames):
            raise InputError(f"loop must be between 1 and n_frames - 1 = {int(n_frames) - 1}, got {overlap}")
        total = int(n_frames) + overlap

        def report(progress):
            if callback is not None:
                callback(progress if progress.stage != "frames" else Progress("frames", progress.done, total))

        head = []
        for frame in self.animate(total, shape, rng=rng, callback=report):
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
