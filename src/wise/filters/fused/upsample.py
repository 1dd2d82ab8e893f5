"""Fused kernel of :func:`wise.filters.upsample.joint_bilateral_upsample`: the normalized sum over
the low-resolution neighbours (Kopf et al. 2007), forward and analytic backward, in Dr.Jit.

Per output pixel ``p`` and neighbour ``q`` (low-resolution pixel ``(r, s)``, the rows and columns
chosen by ``upsample._axis_neighbours``): ``d = guide(p) - guide_low(q)``,
``e = max(max(|d|^2 a_r(p), F_r) + (dy^2 + dx^2) a_s(p), F)`` with the coefficients
``a = -1 / (2 sigma^2)`` and the floors ``F_r``, ``F``; ``w = exp(e)`` and
``out(p) = sum_q w low(q) / sum_q w``.

The PyTorch path gathers every neighbour as a full-resolution tensor (twice in backward, whose
gathers scatter into zero-filled tensors); here a lane (an output pixel) reads its neighbours from
one small channels-last copy of the low-resolution result and guide, and backward scatters into
per-thread copies of one low-resolution accumulator. A symbolic loop visits the rows of neighbours,
the neighbours of a row unrolled, which keeps the kernels small (they compile in a fraction of a
second).
"""

from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import torch
from drjit.llvm import UInt32

from wise.filters.fused import reduce_to
from wise.filters.fused._drjit import flat, float_type, kernel_threads, to_torch
from wise.filters.fused._lanes import Grid, maximum, runtime

_RGB = 3
"""Channels of the result and of the guide of the effects' case (RGB or Lab), which enters through
:func:`_forward_rgb`; the trace is specialized to the channel counts either way."""


@dataclass
class _Inputs:
    """The kernel's inputs: one lane per output pixel, the low-resolution ``packed`` result and
    guide ``(B, h, w, C + G)`` and the neighbour tables ``(N, H)``, ``(N, W)`` as flat arrays."""

    grid: Grid
    packed: object
    channels: int
    guide_channels: int
    low_height: int
    low_width: int
    guide: list
    a_spatial: object
    a_range: object
    n: int
    rows: object
    rows_sq: object
    cols: object
    cols_sq: object
    row: object
    column: object
    range_floor: float
    floor: float

    @classmethod
    def of(cls, low, guide_low, guide, a_spatial, a_range, rows, rows_sq, cols, cols_sq, floors) -> "_Inputs":
        b, c, h, w = low.shape
        g, height, width = guide.shape[1:]
        Float = float_type(low.dtype)
        grid = Grid(b, height, width, Float)
        packed = torch.cat((low.detach(), guide_low.detach().to(low.dtype)), dim=1).permute(0, 2, 3, 1)
        guide_pixels = flat(guide.to(low.dtype), Float)
        return cls(
            grid,
            flat(packed, Float),
            c,
            g,
            h,
            w,
            [grid.load(guide_pixels, k, g) for k in range(g)],
            grid.load_broadcast(a_spatial),
            grid.load_broadcast(a_range),
            rows.shape[0],
            flat(rows.to(torch.int32), UInt32),
            flat(rows_sq.to(low.dtype), Float),
            flat(cols.to(torch.int32), UInt32),
            flat(cols_sq.to(low.dtype), Float),
            grid.row,
            grid.column,
            *(runtime(Float, floor) for floor in floors),
        )


@dataclass
class _Neighbour:
    """Neighbour ``(j, i)`` of the lane's pixel: where it starts in ``packed``, its values (result
    channels, then guide channels), the guide's differences to it and its weight's terms."""

    start: object
    values: list
    differences: list
    spatial_sq: object
    range_sq: object
    range_term: object
    exponent: object
    weight: object

    @classmethod
    def of(cls, inputs: _Inputs, row_start, row_sq, column, column_sq) -> "_Neighbour":
        """The neighbour in the row starting at ``row_start`` in ``packed`` and in ``column``, at the
        squared distances ``row_sq`` and ``column_sq`` from the pixel."""
        Float, c = inputs.grid.Float, inputs.channels
        stride = c + inputs.guide_channels
        start = (row_start + column) * stride
        values = [dr.gather(Float, inputs.packed, start + k) for k in range(stride)]
        differences = [centre - value for centre, value in zip(inputs.guide, values[c:])]
        range_sq = Float(0.0)
        for difference in differences:
            range_sq = dr.fma(difference, difference, range_sq)
        range_term = range_sq * inputs.a_range
        spatial_sq = row_sq + column_sq
        exponent = maximum(range_term, inputs.range_floor) + spatial_sq * inputs.a_spatial
        weight = dr.exp(maximum(exponent, inputs.floor))
        return cls(start, values, differences, spatial_sq, range_sq, range_term, exponent, weight)


def _visit(inputs: _Inputs, state: tuple, step) -> tuple:
    """``state = step(neighbour, *state)`` over every neighbour: a symbolic loop over the ``N``
    neighbouring rows, the ``N`` columns of each unrolled (their indices gathered once)."""
    grid, n = inputs.grid, inputs.n
    Float = grid.Float
    columns = []
    for i in range(n):
        at = i * grid.runtime_width + inputs.column
        columns.append((dr.gather(UInt32, inputs.cols, at), dr.gather(Float, inputs.cols_sq, at)))

    def body(j, *state):
        at = j * grid.runtime_height + inputs.row
        low_height, low_width = runtime(UInt32, inputs.low_height), runtime(UInt32, inputs.low_width)
        row_start = (grid.picture * low_height + dr.gather(UInt32, inputs.rows, at)) * low_width
        row_sq = dr.gather(Float, inputs.rows_sq, at)
        for column, column_sq in columns:
            state = step(_Neighbour.of(inputs, row_start, row_sq, column, column_sq), *state)
        return (j + 1, *state)

    return dr.while_loop((UInt32(0), *state), lambda j, *_: j < n, body)[1:]


def _sum_forward(inputs: _Inputs):
    """``out`` (``C`` arrays) and ``norm = sum_q w``, evaluated in one kernel."""
    c = inputs.channels

    def step(neighbour: _Neighbour, norm, *totals):
        weight = neighbour.weight
        return (norm + weight, *[dr.fma(weight, value, total) for value, total in zip(neighbour.values, totals)])

    Float = inputs.grid.Float
    norm, *totals = _visit(inputs, (Float(0.0), *[Float(0.0) for _ in range(c)]), step)
    out = [total / norm for total in totals]
    dr.eval(*out, norm)
    return out, norm


def _forward_rgb(inputs: _Inputs):
    """:func:`_sum_forward` for three channels and a three-channel guide (the effects' case)."""
    return _sum_forward(inputs)


def _forward_any(inputs: _Inputs):
    """:func:`_sum_forward` for any numbers of channels."""
    return _sum_forward(inputs)


def _backward(inputs: _Inputs, out: list, norm, grad: list, need_low: bool, need_guide_low: bool):
    """Gradients of :func:`_sum_forward`. With ``g`` the output's gradient,
    ``dL/dw_q = sum_c g_c (low_c(q) - out_c) / norm``; ``dL/de = w dL/dw`` unless clamped, which
    reaches ``a_s`` (times the squared distance), ``a_r`` (times ``|d|^2``) and, through
    ``2 a_r d``, the guide at ``p`` (per lane) and the downsampled guide at ``q`` (scattered into
    the flat ``(B, h, w, C + G)`` gradient of ``packed``; the result's gradient ``w g / norm``
    likewise). Returns that gradient (or ``None``) and the per-lane ``[*g_guide, g_a_s, g_a_r]``."""
    grid, c, g = inputs.grid, inputs.channels, inputs.guide_channels
    Float = grid.Float
    inverse_norm = 1.0 / norm
    scaled = [value * inverse_norm for value in grad]
    g_dot_out = Float(0.0)
    for s, o in zip(scaled, out):
        g_dot_out = dr.fma(s, o, g_dot_out)
    scatter = need_low or need_guide_low
    g_packed = dr.zeros(Float, grid.batch * inputs.low_height * inputs.low_width * (c + g)) if scatter else None
    mode = dr.ReduceMode.Expand

    def step(neighbour: _Neighbour, g_s, g_r, *g_guide):
        g_weight = -g_dot_out
        for s, value in zip(scaled, neighbour.values):
            g_weight = dr.fma(s, value, g_weight)
        if need_low:
            for k, s in enumerate(scaled):
                dr.scatter_add(g_packed, neighbour.weight * s, neighbour.start + k, mode=mode)
        g_exponent = dr.select(neighbour.exponent >= inputs.floor, g_weight * neighbour.weight, 0.0)
        g_s = dr.fma(g_exponent, neighbour.spatial_sq, g_s)
        g_range = dr.select(neighbour.range_term >= inputs.range_floor, g_exponent, 0.0)
        g_r = dr.fma(g_range, neighbour.range_sq, g_r)
        g_difference = 2.0 * g_range * inputs.a_range
        through = [g_difference * difference for difference in neighbour.differences]
        if need_guide_low:
            for k, value in enumerate(through):
                dr.scatter_add(g_packed, -value, neighbour.start + c + k, mode=mode)
        return (g_s, g_r, *[total + value for total, value in zip(g_guide, through)])

    outputs = list(_visit(inputs, tuple(Float(0.0) for _ in range(2 + g)), step))
    outputs = [*outputs[2:], *outputs[:2]]
    dr.eval(*outputs, *([g_packed] if scatter else []))
    return g_packed, outputs


class JointBilateralSum(torch.autograd.Function):
    """``sum_q w_q low(q) / sum_q w_q`` of :func:`wise.filters.upsample.joint_bilateral_upsample`
    for ``low`` ``(B, C, h, w)``, ``guide_low`` ``(B, G, h, w)`` (the guide area-downsampled),
    ``guide`` ``(B, G, H, W)`` and the coefficients ``a_spatial``, ``a_range`` (``-1 / (2 sigma^2)``,
    broadcasting to ``(B, 1, H, W)``); ``rows``/``cols`` ``(N, H)``/``(N, W)`` are the
    low-resolution neighbours of every output row and column and ``rows_sq``/``cols_sq`` their
    squared distances. Gradients reach ``low``, both guides and both coefficients."""

    @staticmethod
    def forward(  # type: ignore[override]
        ctx,
        low: torch.Tensor,
        guide_low: torch.Tensor,
        guide: torch.Tensor,
        a_spatial: torch.Tensor,
        a_range: torch.Tensor,
        rows: torch.Tensor,
        rows_sq: torch.Tensor,
        cols: torch.Tensor,
        cols_sq: torch.Tensor,
        range_floor: float,
        floor: float,
    ) -> torch.Tensor:
        b, c = low.shape[:2]
        height, width = guide.shape[-2:]
        tensors = (low, guide_low, guide, a_spatial, a_range, rows, rows_sq, cols, cols_sq)
        kernel = _forward_rgb if c == _RGB and guide.shape[1] == _RGB else _forward_any
        with kernel_threads():
            out, norm = kernel(_Inputs.of(*tensors, (range_floor, floor)))
            result = to_torch(out, (b, height, width))
            norm = norm.torch().view(b, 1, height, width)
        ctx.save_for_backward(*tensors, result, norm)
        ctx.floors = (range_floor, floor)
        return result

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        *tensors, out, norm = ctx.saved_tensors
        low, _, guide, a_spatial, a_range = tensors[:5]
        b, c, h, w = low.shape
        g_channels, height, width = guide.shape[1:]
        need = ctx.needs_input_grad
        with kernel_threads():
            inputs = _Inputs.of(*tensors, ctx.floors)
            grid = inputs.grid
            Float = grid.Float
            outs = flat(out, Float)
            grads = flat(grad.to(low.dtype), Float, (b, c, height, width))
            g_packed, outputs = _backward(
                inputs,
                [grid.load(outs, k, c) for k in range(c)],
                grid.load(flat(norm, Float)),
                [grid.load(grads, k, c) for k in range(c)],
                need[0],
                need[1],
            )
            g_guide = to_torch(outputs[:g_channels], (b, height, width))
            g_a_spatial, g_a_range = (to_torch([o], (b, height, width)) for o in outputs[g_channels:])
            if g_packed is not None:
                g_packed = g_packed.torch().view(b, h, w, c + g_channels).permute(0, 3, 1, 2)
        return (
            g_packed[:, :c].contiguous() if need[0] else None,
            g_packed[:, c:].contiguous() if need[1] else None,
            g_guide if need[2] else None,
            reduce_to(g_a_spatial, a_spatial.shape) if need[3] else None,
            reduce_to(g_a_range, a_range.shape) if need[4] else None,
            None,
            None,
            None,
            None,
            None,
            None,
        )
