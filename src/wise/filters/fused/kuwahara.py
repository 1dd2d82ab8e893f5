"""Fused kernel of :func:`wise.filters.kuwahara.anisotropic_kuwahara` after the ellipse is set up:
the sample loop of ``_SectorSums`` and the sector blend that follows it (Kyprianidis, Kang &
Döllner 2009), forward and analytic backward, in Dr.Jit.

Per pixel ``p`` (centre value ``I``) and tap ``t`` at unit-disc position ``(u_t, v_t)``: the
bilinear, border-clamped sample ``s_t`` at ``p + u_t M + v_t N`` (``M``, ``N`` the major and minor
axis vectors in pixels), ``d_t = s_t - I``, and per sector ``n`` the sums
``S_n = sum_t w_tn d_t`` and ``Q_n = sum_t w_tn |d_t|^2``. With ``T`` the weight of a sector:
means ``m_n = S_n / T``, variances ``v_n = Q_n / T - |m_n|^2``, logits
``l_n = -softplus(q / 2 log(K max(v_n, 0) + eps))`` and the output ``I + sum_n softmax(l)_n m_n``.

The PyTorch path holds the sums and every step of the blend as ``(sectors, B, C, H, W)`` tensors;
here each lane is a pixel and its sectors' sums stay in registers. The taps are rings of one tap
per sector; the kernels loop over the sectors, turning the sectors' sums by one place each time,
so that a tap always adds to the same places (its sector and the neighbour it leans towards),
and unroll the rings (forward) or loop over them too (backward, whose scatters would make the
unrolled code slow to compile); the channels and the blend's sectors unroll. When a gradient is
wanted, forward keeps the sums (``sectors * (C + 1)`` arrays of one value a pixel) and backward
recomputes the samples once, for the gradients of the sums, and scatters the image's gradient
through them; no per-sample value is kept. Arithmetic is in the image's dtype.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Sequence

import drjit as dr
import numpy as np
import torch
from drjit.llvm import UInt32

from wise.filters.fused import reduce_to
from wise.filters.fused._drjit import flat, float_type, kernel_threads, to_torch
from wise.filters.fused._lanes import Grid, PackedGradient, minimum, runtime

_SOFTPLUS_GROWTH_THRESHOLD = math.exp(20.0)
"""``exp`` of the input above which :func:`torch.nn.functional.softplus` returns its input (its
default ``threshold`` is 20)."""
_MAX_INTEGER_POWER = 64
"""Largest whole ``q / 2`` raised by multiplications instead of ``exp`` and ``log``."""
_POWER_STEPS = _MAX_INTEGER_POWER.bit_length() - 1
"""Squarings of :func:`_lane_power`, enough for every exponent up to :data:`_MAX_INTEGER_POWER`."""
_SLOTS = 2
"""Sectors a tap can weigh in: its own and the neighbour it leans towards."""
_BY_EXP, _MIXED = 0, -1
"""How :func:`_power_plan` has ``(K max(v, 0) + eps)^(q / 2)`` raised where it is no single whole power."""


@lru_cache(maxsize=16)
def tap_arrays(taps: Sequence) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The taps of ``kuwahara._sample_layout`` as arrays: unit-disc positions ``(T, 2)`` (along,
    across), sector indices ``(T, 2)`` and sector weights ``(T, 2)`` (0 in an unused slot)."""
    positions = np.zeros((len(taps), 2))
    sector_index = np.zeros((len(taps), _SLOTS), dtype=np.int64)
    sector_weight = np.zeros((len(taps), _SLOTS))
    for t, tap in enumerate(taps):
        positions[t] = tap.along, tap.across
        for slot, (sector, weight) in enumerate(tap.sector_weights):
            sector_index[t, slot] = sector
            sector_weight[t, slot] = weight
    return positions, sector_index, sector_weight


@dataclass(frozen=True)
class _Ring:
    """One ring of taps of ``kuwahara._sample_layout``: tap ``i`` lies at ``positions[i]`` and
    weighs ``own`` in sector ``i``, ``after`` in sector ``i + 1`` and ``before`` in sector ``i - 1``
    (at most one of the last two nonzero: the neighbour the ring leans towards)."""

    own: float
    after: float
    before: float
    positions: tuple[tuple[float, float], ...]


@dataclass(frozen=True)
class _Layout:
    """The taps as rings of one tap per sector (the kernels loop over the sectors, so that the
    traced code holds one tap a ring: every tap unrolled took seconds to compile), every sector's
    total tap weight ``W_n`` and the blend's constants."""

    rings: tuple[_Ring, ...]
    sector_weights: tuple[float, ...]
    total_weight: float
    variance_scale: float
    variance_eps: float

    @classmethod
    def of(cls, taps: Sequence, sectors: int, total_weight: float, variance_scale: float, variance_eps: float):
        """The layout of ``taps`` in the order of ``kuwahara._sample_layout``: ring by ring, tap ``i``
        of a ring on sector ``i``'s side; a ``ValueError`` for taps that do not make such rings."""
        positions, index, weight = tap_arrays(taps)
        if len(taps) % sectors:
            raise ValueError(f"{len(taps)} taps do not make rings of {sectors} sectors")
        rings = []
        for start in range(0, len(taps), sectors):
            own, after, before = set(), set(), set()
            for i in range(sectors):
                shares = {n: 0.0 for n in range(sectors)}
                for n, w in zip(index[start + i], weight[start + i]):
                    shares[int(n)] += float(w)
                rest = {n for n in shares if n not in (i, (i + 1) % sectors, (i - 1) % sectors)}
                if any(shares[n] != 0.0 for n in rest):
                    raise ValueError("a tap weighs in a sector neither its own nor a neighbour")
                own.add(shares[i])
                if sectors == 2:  # one neighbour, both ways round
                    after.add(shares[(i + 1) % sectors])
                    before.add(0.0)
                else:
                    after.add(shares[(i + 1) % sectors])
                    before.add(shares[(i - 1) % sectors])
            if max(len(own), len(after), len(before)) > 1:
                raise ValueError("the taps of a ring weigh differently")
            ring_positions = tuple((float(u), float(v)) for u, v in positions[start : start + sectors])
            rings.append(_Ring(own.pop(), after.pop(), before.pop(), ring_positions))
        sector_weights = [float(w) for w in np.bincount(index.reshape(-1), weight.reshape(-1), minlength=sectors)]
        return cls(tuple(rings), tuple(sector_weights), float(total_weight), float(variance_scale), float(variance_eps))

    @property
    def sectors(self) -> int:
        return len(self.sector_weights)

    def over_sectors(self, Float, rotating: list, state: tuple, body, ring_loop: bool = False) -> tuple[list, tuple]:
        """Run ``body`` over the sectors ``i`` in a Dr.Jit loop, with the taps of every ring on
        sector ``i``'s axis: ``rotating, state = body(taps, rotating, state)``, once for all rings
        (unrolled) or, with ``ring_loop``, once a ring in an inner loop (a smaller kernel).

        ``rotating`` holds one tuple of arrays per sector, turned by one sector each time, so
        that ``body`` finds sector ``i`` in place 0, ``i + 1`` in place 1 and ``i - 1`` in the
        last: ``taps`` lists each tap's position and the ``(place, weight)`` it weighs in (Dr.Jit
        arrays in the loops). Both come back in the sectors' order."""
        sectors, rings, size = self.sectors, len(self.rings), len(rotating[0])
        positions = Float([value for i in range(sectors) for ring in self.rings for value in ring.positions[i]])
        weights = Float([value for ring in self.rings for value in (ring.own, ring.after, ring.before)])
        neighbours = sorted({0, 1, sectors - 1})  # the places a tap weighs in
        if sectors == 2:  # one neighbour: every weight outside the own sector is in ``after``
            neighbours = [0, 1]

        def position(i, j):
            first = (i * rings + j) * 2
            return dr.gather(Float, positions, first), dr.gather(Float, positions, first + 1)

        def weigh(ring):
            return [(place, w) for place, w in zip((0, 1, sectors - 1), ring) if isinstance(w, Float) or w != 0.0]

        def ring_taps(i, turned, rest):
            if not ring_loop:
                taps = [
                    (position(i, j), weigh((ring.own, ring.after, ring.before))) for j, ring in enumerate(self.rings)
                ]
                return body(taps, turned, rest)

            def one_ring(j, *values):
                near = [values[k * size : (k + 1) * size] for k in range(len(neighbours))]
                places = dict(zip(neighbours, near))
                ring = [dr.gather(Float, weights, j * 3 + m) for m in range(2 if sectors == 2 else 3)]
                turned_here = [places.get(n, group) for n, group in enumerate(turned)]
                turned_here, rest = body(
                    [(position(i, j), weigh(ring))], turned_here, tuple(values[len(near) * size :])
                )
                return (j + 1, *(value for n in neighbours for value in turned_here[n]), *rest)

            _, *values = dr.while_loop(
                state=(UInt32(0), *(value for n in neighbours for value in turned[n]), *rest),
                cond=lambda j, *_: j < rings,
                body=one_ring,
                label="rings",
            )
            turned = list(turned)
            for k, n in enumerate(neighbours):
                turned[n] = tuple(values[k * size : (k + 1) * size])
            return turned, tuple(values[len(neighbours) * size :])

        def loop_body(i, *values):
            turned = [values[n * size : (n + 1) * size] for n in range(sectors)]
            turned, rest = ring_taps(i, turned, tuple(values[sectors * size :]))
            turned = list(turned[1:]) + list(turned[:1])
            return (i + 1, *(value for group in turned for value in group), *rest)

        _, *values = dr.while_loop(
            state=(UInt32(0), *(value for group in rotating for value in group), *state),
            cond=lambda i, *_: i < sectors,
            body=loop_body,
            label="sectors",
        )
        return [tuple(values[n * size : (n + 1) * size]) for n in range(sectors)], tuple(values[sectors * size :])


def _power_plan(sharpness: torch.Tensor) -> int:
    """How the kernel raises ``g_n = (K max(v_n, 0) + eps)^(q / 2)``: by multiplications where
    ``q / 2`` is a whole number in ``[1, 64]`` (``q = 8``: the fourth power), else by ``exp`` and
    ``log``. Returns that whole number where every pixel has the same one (the kernel multiplies
    by a fixed sequence), :data:`_BY_EXP` where no pixel has one, :data:`_MIXED` otherwise
    (decided per lane)."""
    half = 0.5 * sharpness.detach()
    whole = (half >= 1.0) & (half <= _MAX_INTEGER_POWER) & (half == half.floor())
    if not bool(whole.any()):
        return _BY_EXP
    first = half.reshape(-1)[0]
    if bool(whole.all()) and bool((half == first).all()):
        return int(first)
    return _MIXED


def _power(base, exponent: int):
    """``base ** exponent`` for a whole ``exponent >= 1`` by repeated squaring (the multiplications
    of :func:`_lane_power` for that exponent)."""
    result = None
    while exponent > 1:
        if exponent & 1:
            result = base if result is None else result * base
        base = base * base
        exponent >>= 1
    return base if result is None else result * base


def _lane_power(base, exponent):
    """``base ** exponent`` for a per-lane whole ``exponent`` in ``[1, 64]``, by repeated squaring."""
    result = dr.ones(type(base), dr.width(base))
    for _ in range(_POWER_STEPS):
        active = exponent > 1
        result = dr.select(active & ((exponent & 1) != 0), result * base, result)
        base = dr.select(active, base * base, base)
        exponent = dr.select(active, exponent >> 1, exponent)
    return result * base


@dataclass
class _Inputs:
    """The kernel's inputs: the flat image, each lane's centre colour, axes in pixels and ``q``."""

    grid: Grid
    image: object
    channels: int
    centre: list
    major_x: object
    major_y: object
    minor_x: object
    minor_y: object
    sharpness: object

    @classmethod
    def of(cls, image: torch.Tensor, major: torch.Tensor, minor: torch.Tensor, sharpness: torch.Tensor) -> "_Inputs":
        b, c, h, w = image.shape
        Float = float_type(image.dtype)
        grid = Grid(b, h, w, Float)
        pixels = flat(image, Float)
        lane = grid.picture * grid.runtime_plane + grid.pixel
        half_width, half_height = runtime(Float, 0.5 * (w - 1)), runtime(Float, 0.5 * (h - 1))

        def axes(vectors: torch.Tensor):  # (B, H, W, 2) in grid units, to pixels
            values = flat(vectors.to(image.dtype), Float, (b, h, w, 2))
            x = dr.gather(Float, values, lane * 2)
            y = dr.gather(Float, values, lane * 2 + 1)
            return x * half_width, y * half_height

        q = sharpness.to(image.dtype)
        if q.shape[-2:] == (1, 1):  # one value a picture: read by the lane's picture
            q_lanes = dr.gather(Float, flat(q, Float, (b, 1, 1, 1)), grid.picture)
        else:
            q_lanes = grid.load(flat(q, Float, (b, 1, h, w)))
        return cls(
            grid,
            pixels,
            c,
            [grid.load(pixels, k, c) for k in range(c)],
            *axes(major),
            *axes(minor),
            q_lanes,
        )

    def locate_tap(self, along: float, across: float):
        grid = self.grid
        x = grid.x + along * self.major_x + across * self.minor_x
        y = grid.y + along * self.major_y + across * self.minor_y
        return grid.locate(x, y)


@dataclass
class _Blend:
    """Per sector: the blend's weight ``softmax(l)_n`` and what its gradient needs."""

    shares: list
    variances: list
    deviations: list
    log_deviations: list
    slopes: list  # the derivative of the softplus at e_n


def _blend(sums: list, squares: list, q, layout: _Layout, plan: int) -> _Blend:
    """``exp(l_n) = 1 / (1 + g_n)`` with ``g_n = (K max(v_n, 0) + eps)^(q / 2) = exp(e_n)`` (see
    :func:`_power_plan`). Above the softplus threshold ``l_n = -e_n``, ``exp(l_n) = 1 / g_n``;
    where every ``e_n`` lies above it the softmax is taken relative to the smallest, so that no
    weight underflows."""
    total = layout.total_weight
    half = 0.5 * q
    if plan == _MIXED:
        whole = (half >= 1.0) & (half <= _MAX_INTEGER_POWER) & (half == dr.floor(half))
        exponent = dr.select(whole, UInt32(half), 1)
    variances, deviations, log_deviations, exponents, growths = [], [], [], [], []
    for channel_sums, square in zip(sums, squares):
        mean_square = 0.0
        for value in channel_sums:
            mean = value / total
            mean_square = dr.fma(mean, mean, mean_square)
        variance = square / total - mean_square
        deviation = dr.select(variance > 0.0, variance, 0.0) * layout.variance_scale + layout.variance_eps
        log_deviation = dr.log(deviation)
        e = half * log_deviation
        if plan > 0:
            growth = _power(deviation, plan)
        elif plan == _BY_EXP:
            growth = dr.exp(e)
        else:
            growth = dr.select(whole, _lane_power(deviation, exponent), dr.exp(e))
        variances.append(variance)
        deviations.append(deviation)
        log_deviations.append(log_deviation)
        exponents.append(e)
        growths.append(growth)
    smallest, least_exponent = growths[0], exponents[0]
    for growth, e in zip(growths[1:], exponents[1:]):
        smallest, least_exponent = minimum(smallest, growth), minimum(least_exponent, e)
    all_above = smallest > _SOFTPLUS_GROWTH_THRESHOLD  # every logit is -e_n (g_n may have overflowed)
    shares, slopes = [], []
    normaliser = 0.0
    for growth, e in zip(growths, exponents):
        above = growth > _SOFTPLUS_GROWTH_THRESHOLD
        below_share = 1.0 / (1.0 + growth)
        share = dr.select(all_above, dr.exp(least_exponent - e), dr.select(above, 1.0 / growth, below_share))
        slopes.append(dr.select(all_above | above, 1.0, growth * below_share))
        shares.append(share)
        normaliser = normaliser + share
    return _Blend([share / normaliser for share in shares], variances, deviations, log_deviations, slopes)


def _forward(inputs: _Inputs, layout: _Layout, plan: int, keep: bool):
    """The output's channels, and the sums ``S_n`` (``sectors x C``) and ``Q_n`` when ``keep``."""
    grid, channels, image = inputs.grid, inputs.channels, inputs.image
    sectors, lanes = layout.sectors, grid.lanes
    starts = [grid.channel_start(k, channels) for k in range(channels)]

    def sector_taps(taps: list, turned: list, state: tuple) -> tuple[list, tuple]:
        sums = [list(group) for group in turned]  # each place: the channels' S, then Q
        for (along, across), places in taps:
            corners = inputs.locate_tap(along, across)
            square = 0.0
            for k, (start, centre) in enumerate(zip(starts, inputs.centre)):
                difference = grid.sample(image, corners, start) - centre
                square = dr.fma(difference, difference, square)
                for place, weight in places:
                    sums[place][k] = dr.fma(weight, difference, sums[place][k])
            for place, weight in places:
                sums[place][channels] = dr.fma(weight, square, sums[place][channels])
        return sums, state

    zeros = [tuple(dr.zeros(grid.Float, lanes) for _ in range(channels + 1)) for _ in range(sectors)]
    groups, _ = layout.over_sectors(grid.Float, zeros, (), sector_taps)
    sums = [list(group[:channels]) for group in groups]
    squares = [group[channels] for group in groups]
    kept = [value for channel_sums in sums for value in channel_sums] + squares
    shares = _blend(sums, squares, inputs.sharpness, layout, plan).shares
    out = []
    for k, centre in enumerate(inputs.centre):
        blended = 0.0
        for share, channel_sums in zip(shares, sums):
            blended = dr.fma(share, channel_sums[k], blended)
        out.append(centre + blended / layout.total_weight)
    kept = kept if keep else []
    dr.eval(*out, *kept)
    return out, kept


def _backward(inputs: _Inputs, layout: _Layout, plan: int, kept: list, grad, needs: tuple):
    """Gradients of the output through the kept sums: ``needs`` says which of (image, major,
    minor, sharpness) are wanted. Returns the image's scattered gradient (or ``None``) and the
    per-lane gradients: the centre's channels, the major and minor axes' x and y (in grid units)
    and ``q``, each ``None`` where it is not wanted."""
    need_image, need_major, need_minor, need_sharpness = needs
    grid, channels, image = inputs.grid, inputs.channels, inputs.image
    Float, total = grid.Float, layout.total_weight
    sectors = layout.sectors
    starts = [grid.channel_start(k, channels) for k in range(channels)]
    sums = [kept[n * channels : (n + 1) * channels] for n in range(sectors)]
    squares = kept[sectors * channels :]
    g = [grid.load(grad, k, channels) for k in range(channels)]
    q = inputs.sharpness
    blend = _blend(sums, squares, q, layout, plan)

    # the blend's backward: gradients of S_n and Q_n, and of q
    g_shares = []
    mean_g_share = 0.0  # sum_n a_n dL/da_n, for the softmax
    for share, channel_sums in zip(blend.shares, sums):
        g_share = 0.0
        for g_k, value in zip(g, channel_sums):
            g_share = dr.fma(g_k, value, g_share)
        g_share = g_share / total
        g_shares.append(g_share)
        mean_g_share = dr.fma(share, g_share, mean_g_share)
    g_q = Float(0.0)
    g_sums, g_squares = [], []
    for n in range(sectors):
        # l_n = -softplus(e_n), e_n = q / 2 log(K max(v_n, 0) + eps)
        share = blend.shares[n]
        g_exponent = -share * (g_shares[n] - mean_g_share) * blend.slopes[n]
        if need_sharpness:
            g_q = dr.fma(g_exponent * 0.5, blend.log_deviations[n], g_q)
        # clamp_min passes the gradient at 0
        g_variance = dr.select(
            blend.variances[n] >= 0.0, g_exponent * 0.5 * q * layout.variance_scale / blend.deviations[n], 0.0
        )
        g_squares.append(g_variance / total)
        g_sums.append([(share * g_k - 2.0 * (value / total) * g_variance) / total for g_k, value in zip(g, sums[n])])

    # the taps' backward: d_t enters S_n linearly and Q_n through |d_t|^2
    g_image = PackedGradient(grid, channels) if need_image else None

    def sector_taps(taps: list, turned: list, state: tuple) -> tuple[list, tuple]:
        g_major_x, g_major_y, g_minor_x, g_minor_y = state
        for (along, across), places in taps:
            corners = inputs.locate_tap(along, across)
            g_square = 0.0
            for place, weight in places:
                g_square = dr.fma(2.0 * weight, turned[place][channels], g_square)
            g_x, g_y = 0.0, 0.0
            g_differences = []
            for k, (start, centre) in enumerate(zip(starts, inputs.centre)):
                value, slope_x, slope_y = grid.sample_with_slopes(image, corners, start)
                g_difference = g_square * (value - centre)
                for place, weight in places:
                    g_difference = dr.fma(weight, turned[place][k], g_difference)
                g_differences.append(g_difference)
                g_x = dr.fma(g_difference, slope_x, g_x)
                g_y = dr.fma(g_difference, slope_y, g_y)
            if need_image:
                g_image.scatter(g_differences, corners)
            g_x = dr.select(corners.moves_x, g_x, 0.0)
            g_y = dr.select(corners.moves_y, g_y, 0.0)
            if need_major:
                g_major_x, g_major_y = dr.fma(along, g_x, g_major_x), dr.fma(along, g_y, g_major_y)
            if need_minor:
                g_minor_x, g_minor_y = dr.fma(across, g_x, g_minor_x), dr.fma(across, g_y, g_minor_y)
        return turned, (g_major_x, g_major_y, g_minor_x, g_minor_y)

    # the gradients of each sector's S (channels) and Q, turned with the sectors in the loop; one
    # ring at a time, as the scatters of every ring unrolled take long to compile
    gradients = [(*g_sums[n], g_squares[n]) for n in range(sectors)]
    zeros = tuple(dr.zeros(Float, grid.lanes) for _ in range(4))
    _, (g_major_x, g_major_y, g_minor_x, g_minor_y) = layout.over_sectors(
        Float, gradients, zeros, sector_taps, ring_loop=True
    )
    # back from pixels to grid units
    half_width, half_height = runtime(Float, 0.5 * (grid.width - 1)), runtime(Float, 0.5 * (grid.height - 1))
    axes = [g_major_x * half_width, g_major_y * half_height] if need_major else [None, None]
    axes += [g_minor_x * half_width, g_minor_y * half_height] if need_minor else [None, None]
    g_centre = [None] * channels
    if need_image:
        # the centre enters every d_t: sum_t dL/dd_t = sum_n (W_n dL/dS_n + 2 S_n dL/dQ_n), W_n = sum_t w_tn
        for k in range(channels):
            g_centre_k = g[k]
            for n in range(sectors):
                g_centre_k = g_centre_k - (layout.sector_weights[n] * g_sums[n][k] + 2.0 * sums[n][k] * g_squares[n])
            g_centre[k] = g_centre_k
        g_image.add(g_centre, grid.pixel)
    outputs = [*axes, g_q if need_sharpness else None]
    dr.eval(*(o for o in [g_image.array if need_image else None, *outputs] if o is not None))
    return g_image, outputs


class AnisotropicKuwahara(torch.autograd.Function):
    """The fused ``_SectorSums`` and sector blend of :func:`wise.filters.kuwahara.anisotropic_kuwahara`.

    Inputs: the image ``(B, C, H, W)``, the sampling ellipse's major and minor axis vectors
    ``(B, H, W, 2)`` in grid units (``grid_sample``, ``align_corners=True``), the sharpness ``q``
    (broadcasting to ``(B, 1, H, W)``), the taps of ``_sample_layout``, the number of sectors, the
    weight ``T`` of a sector, the variance scale ``K``, ``eps`` and whether gradients are
    recorded (:func:`torch.is_grad_enabled` of the caller; forward cannot tell). Returns
    ``(B, C, H, W)``; gradients reach the image, both axes and ``q``.
    """

    @staticmethod
    def forward(  # type: ignore[override]
        ctx,
        image: torch.Tensor,
        major: torch.Tensor,
        minor: torch.Tensor,
        sharpness: torch.Tensor,
        taps: Sequence,
        sectors: int,
        total_weight: float,
        variance_scale: float,
        variance_eps: float,
        grad_enabled: bool,
    ) -> torch.Tensor:
        b, c, h, w = image.shape
        layout = _Layout.of(taps, sectors, total_weight, variance_scale, variance_eps)
        plan = _power_plan(sharpness)
        keep = grad_enabled and any(ctx.needs_input_grad)  # the sums for backward, else not kept
        with kernel_threads():
            out, kept = _forward(_Inputs.of(image, major, minor, sharpness), layout, plan, keep)
            out = to_torch(out, (b, h, w))
        ctx.save_for_backward(image, major, minor, sharpness)  # checks that they are not changed in place
        ctx.layout, ctx.plan, ctx.kept = layout, plan, kept
        return out

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        image, major, minor, sharpness = ctx.saved_tensors
        b, c, h, w = image.shape
        needs = tuple(ctx.needs_input_grad[:4])
        with kernel_threads():
            inputs = _Inputs.of(image, major, minor, sharpness)
            grad_flat = flat(grad.to(image.dtype), inputs.grid.Float, (b, c, h, w))
            g_image, outputs = _backward(inputs, ctx.layout, ctx.plan, ctx.kept, grad_flat, needs)
            axes, g_q = outputs[:4], outputs[4]
            if needs[0]:
                g_image = g_image.torch((b, c, h, w))
            g_major = torch.stack([a.torch().view(b, h, w) for a in axes[:2]], dim=-1) if needs[1] else None
            g_minor = torch.stack([a.torch().view(b, h, w) for a in axes[2:]], dim=-1) if needs[2] else None
            g_sharpness = g_q.torch().view(b, 1, h, w) if needs[3] else None
        return (
            g_image,
            reduce_to(g_major, major.shape) if needs[1] else None,
            reduce_to(g_minor, minor.shape) if needs[2] else None,
            reduce_to(g_sharpness, sharpness.shape) if needs[3] else None,
            None,
            None,
            None,
            None,
            None,
            None,
        )
