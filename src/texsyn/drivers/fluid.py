"""The time loop of a fluid-driven dynamic texture (Peyré 2008, section 4, Table 2).

Two parts, both independent of the texture model, which comes in as two functions
(``synthesize`` and ``project``):

* :func:`flow_sequence` evolves the velocity as Table 2 does (advect, diffuse, project onto
  divergence-free fields), with an optional random forcing that keeps the flow turbulent and
  a speed held at the user's value; :func:`looped_flow_sequence` makes it periodic in time.
* :func:`texture_frames` carries the texture with the flow and projects every frame onto the
  model of the current flow. By default the texture is advected by *renewed layers*: each
  layer is one static synthesis sampled through a coordinate map that the flow carries
  (one cubic interpolation from its reference, so no blur accumulates), lives ``renewal``
  frames and fades in and out while the next one takes over, so the stretching a flow
  imposes on any advected material stays bounded; the blend of the two live layers is
  projected onto the model with a few passes of Table 1. ``renewal=0`` is the paper's
  literal loop (the projected frame is advected to make the next one), under which the
  material stretches into long stripes as the frames go on.

``docs/methods/grouplets.md`` ("Dynamic synthesis") explains the choices and their measured
effect.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from ..ops.fluid import (
    advect,
    advect_displacement,
    diffuse,
    prefilter,
    project,
    rescale_speed,
    rms_speed,
    sample_displaced,
    spectral_velocity,
)
from ..ops.progress import Reporter

__all__ = ["FORCING_SLOPE", "FlowDynamics", "flow_sequence", "looped_flow_sequence", "texture_frames"]

#: energy spectrum slope of the forcing above its eddy scale: steep, so the forcing injects
#: energy around one scale (as turbulence forcing does) and the flow itself builds the rest
FORCING_SLOPE = 8.0


@dataclass(frozen=True)
class FlowDynamics:
    """How the velocity evolves from frame to frame.

    Attributes
    ----------
    tau : float
        Time step between frames (Table 2).
    viscosity : float
        Fluid viscosity ``nu`` (pixels^2 per time unit, 5-point Laplacian).
    speed : float
        Root-mean-square displacement per frame in pixels (``tau`` times the RMS velocity).
    keep_speed : bool
        Rescale the velocity to ``speed`` after every step (against viscous decay and
        forcing build-up); otherwise only the initial flow has that speed.
    turbulence : float
        Strength of the random forcing: the fraction of the RMS velocity it adds per frame.
        The forcing is a divergence-free field of eddies of size ``scale`` that changes
        smoothly, with a correlation time of one eddy crossing (``scale / speed`` frames).
    scale : float
        Size of the forced eddies in pixels.
    slope : float
        Energy spectrum slope of the forcing above its peak (``ops.fluid.spectral_velocity``).
    """

    tau: float = 0.5
    viscosity: float = 0.025
    speed: float = 1.0
    keep_speed: bool = True
    turbulence: float = 0.0
    scale: float = 32.0
    slope: float = 3.0

    @property
    def velocity(self) -> float:
        """The RMS velocity in pixels per time unit that moves ``speed`` pixels per frame."""
        return self.speed / self.tau


def flow_sequence(
    initial: np.ndarray, n_frames: int, dynamics: FlowDynamics, rng: np.random.Generator
) -> Iterator[np.ndarray]:
    """Velocities ``V_0 ... V_{n-1}`` of Table 2 (steps 2-4 for the flow), with forcing.

    ``V_0`` is ``initial`` made divergence-free at the set speed; each next one advects the
    last by itself (semi-Lagrangian, cubic), diffuses it implicitly (``tau nu``), adds the
    forcing and projects it onto divergence-free fields (eq. 5).
    """
    tau = dynamics.tau
    velocity = rescale_speed(project(initial), dynamics.velocity)
    shape = velocity.shape[:2]
    forcing = np.zeros_like(velocity)
    memory = 0.0
    if dynamics.turbulence > 0:
        crossing = dynamics.scale / max(dynamics.speed, 1e-6)
        memory = math.exp(-1.0 / max(crossing, 1.0))
        forcing = spectral_velocity(shape, rng, scale=dynamics.scale, slope=FORCING_SLOPE)
    yield velocity
    for _ in range(1, int(n_frames)):
        moved = diffuse(advect(velocity, velocity, tau, order=3), tau * dynamics.viscosity)
        if dynamics.turbulence > 0:
            fresh = spectral_velocity(shape, rng, scale=dynamics.scale, slope=FORCING_SLOPE)
            forcing = memory * forcing + math.sqrt(1.0 - memory**2) * fresh
            moved = moved + (dynamics.turbulence * rms_speed(moved)) * forcing
        velocity = project(moved)
        if dynamics.keep_speed:
            velocity = rescale_speed(velocity, dynamics.velocity)
        yield velocity


def looped_flow_sequence(
    initial: np.ndarray, n_frames: int, closing: int, dynamics: FlowDynamics, rng: np.random.Generator
) -> Iterator[np.ndarray]:
    """Velocities ``V_0 ... V_{n-1}`` of a flow that is periodic in time: ``V_n = V_0``.

    The flow is simulated from ``closing`` frames before frame 0 to frame ``n - 1``; over the
    last ``closing`` frames it is steered onto the same simulation ``n`` frames earlier,
    which is the run-up to ``V_0``, with a smoothstep weight at ``1/(c+1) ... c/(c+1)``
    (``c = closing``) that reaches 1 at frame ``n``, where the field is ``V_0`` exactly.
    Both fields are divergence-free, so their blend is; its RMS speed is interpolated too.
    Every step, the wrap-around included, moves the weight by at most ``1.5 / (c+1)``: a
    short closing turns the flow quickly near the end of the period.
    """
    n, c = int(n_frames), int(closing)
    if not 0 < c < n:
        raise ValueError(f"closing must be between 1 and n_frames - 1 = {n - 1}, got {c}")
    simulated = flow_sequence(initial, n + c, dynamics, rng)
    run_up = [next(simulated) for _ in range(c)]  # times -c .. -1
    for t, velocity in enumerate(simulated):
        if t < n - c:
            yield velocity
            continue
        earlier = run_up[t - (n - c)]  # the simulation at time t - n
        s = (t - (n - c) + 1) / (c + 1)
        w = s * s * (3.0 - 2.0 * s)
        speed = (1.0 - w) * rms_speed(velocity) + w * rms_speed(earlier)
        yield rescale_speed((1.0 - w) * velocity + w * earlier, speed)


@dataclass
class _Layer:
    """One renewed layer: a reference synthesis seen through a coordinate map the flow carries."""

    coefficients: np.ndarray  # cubic B-spline coefficients of the reference (ops.fluid.prefilter)
    displacement: np.ndarray  # (H, W, 2): pixel x of the frame was at x + D(x) in the reference

    def image(self) -> np.ndarray:
        return sample_displaced(self.coefficients, self.displacement)

    def carry(self, step: np.ndarray) -> None:
        self.displacement = advect_displacement(self.displacement, step)


def _births(n_frames: int, renewal: int, loop: bool) -> list[int]:
    """Birth frames ``b_0 = 0 < b_1 < ...`` of the layers, ``renewal / 2`` frames apart.

    An odd ``renewal`` alternates gaps of ``renewal // 2`` and ``renewal // 2 + 1`` frames,
    so each layer lives ``renewal`` frames on average. A loop has ``m >= 2`` births per
    period, evenly spread, and ``b_m = n_frames``.
    """
    if renewal < 2:
        raise ValueError(f"layers must live at least 2 frames, got renewal={renewal}")
    if not loop:
        count = 2 * int(n_frames) // renewal + 2
        return [(k * renewal) // 2 for k in range(count + 1)]
    m = max(2, round(2 * n_frames / renewal))
    return [(k * int(n_frames)) // m for k in range(m + 1)]


def _weights(t: int, start: int, end: int) -> tuple[float, float]:
    """Weights of the layer born at ``start`` (rising) and of the previous one (falling)."""
    s = (t - start) / (end - start)
    return math.sin(0.5 * math.pi * s) ** 2, math.cos(0.5 * math.pi * s) ** 2


def texture_frames(
    velocities: Callable[[], Iterator[np.ndarray]],
    n_frames: int,
    *,
    synthesize: Callable[[np.ndarray], np.ndarray],
    project_texture: Callable[[np.ndarray, np.ndarray], np.ndarray],
    mean: np.ndarray,
    tau: float,
    renewal: int,
    texture_viscosity: float = 0.0,
    loop: bool = False,
    reporter: Reporter | None = None,
    wrap_frame: bool = False,
) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Frames ``(texture, V_t)`` of a dynamic texture (Table 2, steps 2-4 for the texture).

    Parameters
    ----------
    velocities : callable
        Returns a fresh iterator over ``V_0 ... V_{n-1}`` (called twice for a loop, so it
        must give the same fields each time).
    n_frames : int
    synthesize : callable
        ``synthesize(V) -> (H, W, C)``: a static synthesis along ``V`` (a new layer, Table 1
        from noise). Called in frame order, so a random generator it uses gives the same
        layers for the same seed.
    project_texture : callable
        ``project_texture(x, V) -> (H, W, C)``: a few passes of Table 1 from ``x`` along ``V``.
    mean : ndarray, shape (C,)
        Mean of each channel of the model; layers are blended around it with weights whose
        squares sum to one, so that two independent layers keep the contrast of one.
    tau : float
        Time step: the texture moves by ``tau V_t`` from frame ``t`` to ``t + 1``.
    renewal : int
        Frames a layer lives (fading in over the first half, out over the second; at least
        2, and the method asks for 4 so that a layer moves before it fades); 0 for the
        paper's literal loop (advect the last projected frame).
    texture_viscosity : float
        ``nu~``: the advected texture is diffused by ``tau nu~`` before its projection.
    loop : bool
        Make the sequence periodic: ``velocities`` must be periodic (frame ``n`` would be
        frame 0), the layers are born at the same phases in every period and the layer
        alive across the wrap-around is carried through the end of the period first, so
        frame ``n`` would equal frame 0 exactly.
    reporter : Reporter, optional
        Told after every frame.
    wrap_frame : bool
        With ``loop``, also yield frame ``n`` (computed with ``V_n = V_0``), which equals
        frame 0: a check of the wrap-around.
    """
    n = int(n_frames)
    if renewal <= 0:
        if loop:
            raise ValueError("a looping texture needs renewed layers (renewal > 0)")
        yield from _advected_frames(
            velocities(), n, synthesize, project_texture, tau, texture_viscosity, reporter
        )
        return
    births = _births(n, int(renewal), loop)
    wrap: np.ndarray | None = None
    if loop:
        # the layer alive across the wrap-around is born at births[-2] - n: synthesise it
        # along V at births[-2] and carry it through the end of the period to frame 0
        tail = list(_tail(velocities(), n, births[-2]))
        wrap = prefilter(synthesize(tail[0]))
        previous = _Layer(wrap, np.zeros(tail[0].shape))
        for velocity in tail:
            previous.carry(tau * velocity)
    flows = velocities()
    velocity = next(flows)
    if loop and wrap_frame:
        flows = itertools.chain(flows, [velocity])
    if not loop:
        previous = _Layer(prefilter(synthesize(velocity)), np.zeros(velocity.shape))
    k = 0  # index in births of the newest layer, `current`
    current = _Layer(prefilter(synthesize(velocity)), np.zeros(velocity.shape))
    first = current.coefficients
    centre = np.asarray(mean, dtype=np.float64)
    for t in range(n + int(loop and wrap_frame)):
        if t > 0:
            step = tau * velocity
            velocity = next(flows)
            previous.carry(step)
            current.carry(step)
            if t == births[k + 1]:
                k += 1
                if t == n:  # the wrap-around: the birth of frame 0 again
                    fresh = first
                elif loop and k == len(births) - 2 and wrap is not None:
                    fresh = wrap
                else:
                    fresh = prefilter(synthesize(velocity))
                previous, current = current, _Layer(fresh, np.zeros(velocity.shape))
        phase = (0, births[0], births[1]) if t == n else (t, births[k], births[k + 1])
        rising, falling = _weights(*phase)
        norm = math.sqrt(rising**2 + falling**2)
        blend = centre + (rising * (current.image() - centre) + falling * (previous.image() - centre)) / norm
        if texture_viscosity > 0:
            blend = diffuse(blend, tau * texture_viscosity)
        yield project_texture(blend, velocity), velocity
        if reporter is not None:
            reporter(t + 1)


def _tail(flows: Iterator[np.ndarray], n: int, start: int) -> Iterator[np.ndarray]:
    """The velocities of frames ``start ... n - 1``."""
    for t, velocity in enumerate(flows):
        if t >= start:
            yield velocity
        if t == n - 1:
            return


def _advected_frames(flows, n, synthesize, project_texture, tau, texture_viscosity, reporter):
    """The paper's literal loop: advect the last projected frame (cubic), diffuse, project."""
    velocity = next(flows)
    texture = synthesize(velocity)
    for t in range(n):
        if t > 0:
            moved = advect(texture, velocity, tau, order=3)
            velocity = next(flows)
            texture = project_texture(diffuse(moved, tau * texture_viscosity), velocity)
        yield texture, velocity
        if reporter is not None:
            reporter(t + 1)
