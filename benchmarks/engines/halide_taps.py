"""Halide (Python bindings, JIT) ports of two fused Numba kernels, measured against them: the
engine comparison of BENCHMARKS.md ("Choosing the kernel engine"). Needs ``pip install halide numba``
(not dependencies of the package); the Numba kernels are read from commit 420e1e9, their last.

- ``BilateralTaps`` (:mod:`wise.filters.fused.bilateral`): one pass of the oriented bilateral filter.
- ``FlowSmoothingTaps`` (:mod:`wise.filters.fused.dog`): line-integral smoothing along streamlines.

Both forward and backward, float32 arithmetic throughout (the Numba kernels compute in float64
between float32 loads and stores). Halide layout: a NumPy/torch ``(B, C, H, W)`` array is a Halide
buffer ``(x, y, c, b)``. Per-pixel maps are passed as full ``(B, 1, H, W)`` arrays.

Backward: the image gradient is a scatter. Each of ``P`` bands of rows accumulates into its own
private copy of the gradient (an update definition of ``part(x, y, ch, b, p)`` over an RDom of the
band's pixels, parallel over ``p``), and a last stage sums the copies. The per-pixel gradients of
the maps ride along as extra channels of the same accumulator (written at the pixel itself), so each
sample is computed once; the per-sample quantities are computed vectorised over 16 pixels of a row
(``compute_at`` the accumulator's split RVar) and scattered by scalar code (unrolled over sites).

Usage: ``python benchmarks/engines/halide_taps.py --json out.json``
"""

from __future__ import annotations

import os

os.environ.setdefault("HL_NUM_THREADS", "2")  # read by the Halide runtime when its thread pool starts

import argparse
import json
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import halide as hl
import numpy as np
import torch

# ---------------------------------------------------------------- Halide kernels (LOC counted) ---
# HALIDE-KERNELS-BEGIN
SUPPORT = 2.0  # wise.filters.gaussian.SUPPORT
VEC = 16  # float32 lanes of AVX-512
F32 = hl.Float(32)


def _locate(p, size):
    """Clamped bilinear neighbours along one axis: lower, upper, fraction, d(clamped)/dp (0 or 1)."""
    last = size - 1
    pc = hl.clamp(p, 0.0, hl.f32(last))
    i0 = hl.clamp(hl.i32(pc), 0, last)
    i1 = hl.min(i0 + 1, last)
    moves = hl.select((p > 0.0) & (p < hl.f32(last)), hl.f32(1.0), hl.f32(0.0))
    return i0, i1, pc - hl.f32(i0), moves


def _bilinear(img, x0, x1, y0, y1, fx, fy, c, b):
    """Value and x/y slopes of the bilinear sample of channel ``c``."""
    tl, tr, bl, br = img[x0, y0, c, b], img[x1, y0, c, b], img[x0, y1, c, b], img[x1, y1, c, b]
    ts, bs = tr - tl, br - bl
    top, bottom = tl + fx * ts, bl + fx * bs
    return top + fy * (bottom - top), ts + fy * (bs - ts), bottom - top


def _inputs(names, dims=4):
    return [hl.ImageParam(F32, dims, n) for n in names]


def _schedule_output(out, producer, channels):
    """Output (x, y, ch, b): rows in parallel, 16 pixels of a row at a time, the channels unrolled."""
    x, y, ch, b = out.args()
    xo, xi, yb = hl.Var("xo"), hl.Var("xi"), hl.Var("yb")
    out.bound(ch, 0, channels).split(x, xo, xi, VEC).reorder(xi, ch, xo, y, b).unroll(ch).vectorize(xi)
    out.fuse(y, b, yb).parallel(yb)
    if producer is not None:
        producer.compute_at(out, xo).vectorize(producer.args()[0])
    return xo


def _bilateral_sample_geometry(j, s, a, spatial):
    near, far = (2 * j - 1) * s, (2 * j) * s
    w_near, w_far = hl.exp(near * near * a), hl.exp(far * far * a)
    w_pair = hl.max(w_near + w_far, hl.f32(1e-30))
    distance = (near * w_near + far * w_far) / w_pair
    inside = hl.Expr(True) if isinstance(j, int) and j == 1 else (j == 1) | (near <= SUPPORT * spatial)
    return near, far, w_near, w_far, w_pair, distance, inside


def bilateral_forward(channels: int, n: int):
    """Pipeline (image, direction, step, spatial, a, r) -> out (B, C+1, H, W): total, then norm."""
    img, dirn, step, spatial, a, r = args = _inputs(["image", "direction", "step", "spatial", "a", "r"])
    x, y, b, ch = hl.Var("x"), hl.Var("y"), hl.Var("b"), hl.Var("ch")
    W, H = img.width(), img.height()
    s, aa, rr, sp = step[x, y, 0, b], a[x, y, 0, b], r[x, y, 0, b], spatial[x, y, 0, b]
    ux, uy = dirn[x, y, 0, b], dirn[x, y, 1, b]
    centre = [img[x, y, c, b] for c in range(channels)]
    total, norm = [hl.f32(0.0)] * channels, hl.f32(0.0)
    for j in range(1, n + 1):
        _, _, _, _, w_pair, d, inside = _bilateral_sample_geometry(j, s, aa, sp)
        w_pair = hl.select(inside, w_pair, hl.f32(0.0))
        for sign in (1.0, -1.0):
            x0, x1, fx, _ = _locate(hl.f32(x) + sign * d * ux, W)
            y0, y1, fy, _ = _locate(hl.f32(y) + sign * d * uy, H)
            values = [_bilinear(img, x0, x1, y0, y1, fx, fy, c, b)[0] for c in range(channels)]
            range_sq = sum((v - ce) * (v - ce) for v, ce in zip(values, centre))
            w = w_pair * hl.exp(range_sq * rr)
            total = [t + w * v for t, v in zip(total, values)]
            norm = norm + w
    acc, out = hl.Func("bilateral_acc"), hl.Func("bilateral_out")
    acc[x, y, b] = hl.Tuple(total + [norm])
    out[x, y, ch, b] = hl.mux(ch, [acc[x, y, b][i] for i in range(channels + 1)])
    _schedule_output(out, acc, channels + 1)
    return hl.Pipeline(out), args


def _scatter_stage(sites, channels_out, lhs_and_values, producers, rdom_extra, W, H, B, parts):
    """``part(x, y, ch, b, p)``: zero, then for every pixel of band ``p`` (rows ``p*chunk ..``), every
    entry of ``rdom_extra`` and every site: ``part(X, Y, CH, b, p) += value``; returns the sum over parts.

    ``lhs_and_values(site, rx, y, b, extra)`` gives (X, Y, CH, value) for a site index known at
    Python time; the sites are unrolled, the extra RDom dims run as loops."""
    x, y, ch, b, p = (hl.Var(n) for n in ("x", "y", "ch", "b", "p"))
    chunk = (H + parts - 1) / parts
    part, out = hl.Func("part"), hl.Func("grad_out")
    part[x, y, ch, b, p] = hl.f32(0.0)
    dims = (
        [hl.Range(0, sites)]
        + [hl.Range(0, e) for e in rdom_extra]
        + [hl.Range(0, W), hl.Range(0, chunk), hl.Range(0, B)]
    )
    R = hl.RDom(dims)
    rs, extra, rx, ry, rb = (
        R[0],
        [R[1 + i] for i in range(len(rdom_extra))],
        R[len(dims) - 3],
        R[len(dims) - 2],
        R[len(dims) - 1],
    )
    row = p * chunk + ry
    R.where(row < H)
    entries = [lhs_and_values(k, rx, row, rb, extra) for k in range(sites)]
    X, Y, CH, V = (
        hl.mux(rs, [e[i] if isinstance(e[i], hl.Expr) else hl.Expr(e[i]) for e in entries]) for i in range(4)
    )
    part[X, Y, CH, rb, p] = part[X, Y, CH, rb, p] + V
    rp = hl.RDom([hl.Range(0, parts)])
    out[x, y, ch, b] = hl.f32(0.0)
    out[x, y, ch, b] = out[x, y, ch, b] + part[x, y, ch, b, rp.x]
    # schedule
    part.compute_root().vectorize(x, VEC).parallel(p)
    rxo, rxi = hl.RVar("rxo"), hl.RVar("rxi")
    u = part.update(0)
    u.split(rx, rxo, rxi, VEC).reorder(*([rs] + extra + [rxi, rxo, ry, rb, p])).unroll(rs).parallel(p)
    for f in producers:
        f.compute_at(part, rxo).vectorize(f.args()[0])
    xo, xi, yb = hl.Var("xo"), hl.Var("xi"), hl.Var("yb")
    out.bound(ch, 0, channels_out).split(x, xo, xi, VEC).reorder(xi, xo, ch, y, b).vectorize(xi).fuse(
        y, b, yb
    ).parallel(yb)
    out.update(0).split(x, xo, xi, VEC).reorder(xi, rp.x, xo, ch, y, b).vectorize(xi).fuse(y, b, yb).parallel(yb)
    return out


def bilateral_backward(channels: int, n: int):
    """Pipeline (image, direction, step, spatial, a, r, grad_total, grad_norm; parts) -> (B, C+5, H, W):
    grad image, then grad direction x, y, step, a, r."""
    names = ["image", "direction", "step", "spatial", "a", "r", "grad_total", "grad_norm"]
    img, dirn, step, spatial, a, r, gt, gn = args = _inputs(names)
    parts = hl.Param(hl.Int(32), "parts", 2)
    x, y, k, b = hl.Var("x"), hl.Var("y"), hl.Var("k"), hl.Var("b")
    W, H, B = img.width(), img.height(), img.dim(3).extent()
    xx, yy = hl.clamp(x, 0, W - 1), hl.clamp(y, 0, H - 1)  # the last band and block may run past the image
    s, aa, rr, sp = step[xx, yy, 0, b], a[xx, yy, 0, b], r[xx, yy, 0, b], spatial[xx, yy, 0, b]
    ux, uy = dirn[xx, yy, 0, b], dirn[xx, yy, 1, b]
    # per pixel and sample k (j = k // 2 + 1, sign + for even k): corners, fractions, the values to scatter
    j = k / 2 + 1
    sign = hl.f32(1 - 2 * (k % 2))
    near, far, w_near, w_far, w_pair, d, inside = _bilateral_sample_geometry(j, s, aa, sp)
    x0, x1, fx, mx = _locate(hl.f32(xx) + sign * d * ux, W)
    y0, y1, fy, my = _locate(hl.f32(yy) + sign * d * uy, H)
    samples = [_bilinear(img, x0, x1, y0, y1, fx, fy, c, b) for c in range(channels)]
    diffs = [v - img[xx, yy, c, b] for c, (v, _, _) in enumerate(samples)]
    g_tot = [gt[xx, yy, c, b] for c in range(channels)]
    range_sq = sum(dd * dd for dd in diffs)
    g_weight = gn[xx, yy, 0, b] + sum(g * v for g, (v, _, _) in zip(g_tot, samples))
    range_weight = hl.select(inside, hl.exp(range_sq * rr), hl.f32(0.0))
    weight = w_pair * range_weight
    g_log_range = g_weight * weight
    per_diff = 2.0 * g_log_range * rr
    through = [per_diff * dd for dd in diffs]
    g_values = [g * weight + t for g, t in zip(g_tot, through)]
    g_off_x = sign * mx * sum(gv * sx for gv, (_, sx, _) in zip(g_values, samples))
    g_off_y = sign * my * sum(gv * sy for gv, (_, _, sy) in zip(g_values, samples))
    g_w_pair = g_weight * range_weight
    g_dpp = (g_off_x * ux + g_off_y * uy) / w_pair
    g_w_near = g_w_pair + g_dpp * (near - d)
    g_w_far = g_w_pair + g_dpp * (far - d)
    g_near = g_w_near * w_near * 2.0 * near * aa + g_dpp * w_near
    g_far = g_w_far * w_far * 2.0 * far * aa + g_dpp * w_far
    maps = [
        g_off_x * d,
        g_off_y * d,
        g_near * hl.f32(2 * j - 1) + g_far * hl.f32(2 * j),
        g_w_near * w_near * near * near + g_w_far * w_far * far * far,
        g_log_range * range_sq,
    ]
    sv = hl.Func("bilateral_sample")
    sv[x, y, k, b] = hl.Tuple([x0, y0, fx, fy] + g_values + through + maps)
    sv.bound(k, 0, 2 * n).reorder(x, k, y, b)  # k not unrolled: the Tuple elements repeat the whole sample in the IR

    def site(i, rx, row, rb, extra):
        (rk,) = extra
        e = sv[rx, row, rk, rb]
        ex0, ey0, efx, efy = e[0], e[1], e[2], e[3]
        if i < 4 * channels:  # a bilinear corner of channel c
            corner, c = divmod(i, channels)
            cx, cy = corner % 2, corner // 2
            X = hl.min(ex0 + 1, W - 1) if cx else ex0
            Y = hl.min(ey0 + 1, H - 1) if cy else ey0
            wx = efx if cx else 1.0 - efx
            wy = efy if cy else 1.0 - efy
            return X, Y, c, e[4 + c] * wx * wy
        if i < 5 * channels:  # the centre pixel, through the range weight
            c = i - 4 * channels
            return rx, row, c, -e[4 + channels + c]
        m = i - 5 * channels  # gathered gradients of the maps, at the pixel itself
        return rx, row, channels + m, e[4 + 2 * channels + m]

    out = _scatter_stage(5 * channels + 5, channels + 5, site, [sv], [2 * n], W, H, B, parts)
    return hl.Pipeline(out), args + [parts]


def _stream_step(tan, b, px, py, hx, hy, L, W, H):
    """One Euler step along the tangent field: new position, its corners and the next heading."""
    px, py = px + hx * L, py + hy * L
    x0, x1, fx, _ = _locate(px, W)
    y0, y1, fy, _ = _locate(py, H)
    sx = _bilinear(tan, x0, x1, y0, y1, fx, fy, 0, b)[0]
    sy = _bilinear(tan, x0, x1, y0, y1, fx, fy, 1, b)[0]
    flip = hl.select(sx * hx + sy * hy < 0.0, hl.f32(-1.0), hl.f32(1.0))
    scale = flip / hl.max(hl.sqrt(sx * sx + sy * sy), hl.f32(1e-6))
    return px, py, sx * scale, sy * scale, (x0, x1, y0, y1, fx, fy)


def _stream_init(tan, coef, x, y, s, b, L, xx=None, yy=None):
    xx, yy = (x, y) if xx is None else (xx, yy)
    sign = hl.f32(1 - 2 * s)
    unit = L * L * coef[xx, yy, 0, b]
    return [
        hl.f32(xx),
        hl.f32(yy),
        sign * tan[xx, yy, 0, b],
        sign * tan[xx, yy, 1, b],
        hl.exp(unit),
        hl.exp(3.0 * unit),
        hl.exp(2.0 * unit),
    ]


def flow_smoothing_forward(channels: int):
    """Pipeline (image, tangent, sigma, coefficient; steps, step_length) -> (B, C+1, H, W): total, norm."""
    img, tan, sigma, coef = args = _inputs(["image", "tangent", "sigma", "coefficient"])
    steps, L = hl.Param(hl.Int(32), "steps", 1), hl.Param(F32, "step_length", 1.0)
    x, y, s, b, ch = (hl.Var(v) for v in ("x", "y", "s", "b", "ch"))
    W, H = img.width(), img.height()
    state, out = hl.Func("stream"), hl.Func("stream_out")
    state[x, y, s, b] = hl.Tuple(_stream_init(tan, coef, x, y, s, b, L) + [hl.f32(0.0)] * (channels + 1))
    R = hl.RDom([hl.Range(0, steps)])
    old = state[x, y, s, b]
    px, py, hx, hy, (x0, x1, y0, y1, fx, fy) = _stream_step(tan, b, old[0], old[1], old[2], old[3], L, W, H)
    distance = hl.f32(R.x + 1) * L
    w = hl.select((R.x == 0) | (distance <= SUPPORT * sigma[x, y, 0, b]), old[4], hl.f32(0.0))
    values = [_bilinear(img, x0, x1, y0, y1, fx, fy, c, b)[0] for c in range(channels)]
    sums = [old[7 + c] + w * v for c, v in enumerate(values)]
    state[x, y, s, b] = hl.Tuple(
        [px, py, hx, hy, old[4] * old[5], old[5] * old[6], old[6]] + sums + [old[7 + channels] + w]
    )
    both = [state[x, y, 0, b][7 + i] + state[x, y, 1, b][7 + i] for i in range(channels + 1)]
    out[x, y, ch, b] = hl.mux(ch, both)
    _schedule_output(out, state, channels + 1)
    state.bound(s, 0, 2).reorder(x, s, y, b)
    state.update(0).reorder(x, R.x, s, y, b).vectorize(x)
    return hl.Pipeline(out), args + [steps, L]


def flow_smoothing_backward(channels: int):
    """Pipeline (image, tangent, sigma, coefficient, grad_total, grad_norm; steps, step_length, parts)
    -> (B, C+1, H, W): grad image, then grad coefficient."""
    img, tan, sigma, coef, gt, gn = args = _inputs(
        ["image", "tangent", "sigma", "coefficient", "grad_total", "grad_norm"]
    )
    steps, L = hl.Param(hl.Int(32), "steps", 1), hl.Param(F32, "step_length", 1.0)
    parts = hl.Param(hl.Int(32), "parts", 2)
    x, y, s, b, k = (hl.Var(v) for v in ("x", "y", "s", "b", "k"))
    W, H, B = img.width(), img.height(), img.dim(3).extent()
    xx, yy = hl.clamp(x, 0, W - 1), hl.clamp(y, 0, H - 1)
    # path(.., k): the state before step k (position, heading, weight, growth, ratio)
    path = hl.Func("path")
    path[x, y, s, b, k] = hl.Tuple(_stream_init(tan, coef, x, y, s, b, L, xx, yy))
    R = hl.RDom([hl.Range(0, steps)])
    old = path[x, y, s, b, R.x]
    px, py, hx, hy, _ = _stream_step(tan, b, old[0], old[1], old[2], old[3], L, W, H)
    path[x, y, s, b, R.x + 1] = hl.Tuple([px, py, hx, hy, old[4] * old[5], old[5] * old[6], old[6]])
    # tap(.., k): the corners of sample k, its weight and its share of the coefficient's gradient
    tap = hl.Func("tap")
    here, nxt = path[x, y, s, b, k], path[x, y, s, b, k + 1]
    x0, x1, fx, _ = _locate(nxt[0], W)
    y0, y1, fy, _ = _locate(nxt[1], H)
    distance = hl.f32(k + 1) * L
    w = hl.select((k == 0) | (distance <= SUPPORT * sigma[xx, yy, 0, b]), here[4], hl.f32(0.0))
    g_w = gn[xx, yy, 0, b] + sum(
        gt[xx, yy, c, b] * _bilinear(img, x0, x1, y0, y1, fx, fy, c, b)[0] for c in range(channels)
    )
    tap[x, y, s, b, k] = hl.Tuple([x0, y0, fx, fy, w, g_w * w * distance * distance])
    path.reorder(x, k, s, y, b)
    path.update(0).reorder(x, R.x, s, y, b).vectorize(x)
    tap.reorder(x, k, s, y, b)

    def site(i, rx, row, rb, extra):
        rk, rs = extra
        e = tap[rx, row, rs, rb, rk]
        if i < 4 * channels:
            corner, c = divmod(i, channels)
            cx, cy = corner % 2, corner // 2
            X = hl.min(e[0] + 1, W - 1) if cx else e[0]
            Y = hl.min(e[1] + 1, H - 1) if cy else e[1]
            wx = e[2] if cx else 1.0 - e[2]
            wy = e[3] if cy else 1.0 - e[3]
            return X, Y, c, gt[rx, row, c, rb] * e[4] * wx * wy
        return rx, row, channels, e[5]

    out = _scatter_stage(4 * channels + 1, channels + 1, site, [path, tap], [steps, 2], W, H, B, parts)
    return hl.Pipeline(out), args + [steps, L, parts]


# HALIDE-KERNELS-END
# ------------------------------------------------------------------------------ torch wrappers ---

_CACHE: dict = {}
COMPILE_TIMES: dict = {}
TARGET = hl.get_jit_target_from_environment()


def _callable(name, builder, *key):
    if (name, key) not in _CACHE:
        t0 = time.perf_counter()
        pipeline, args = builder(*key)
        t1 = time.perf_counter()
        fn = pipeline.compile_to_callable(args, TARGET)
        t2 = time.perf_counter()
        COMPILE_TIMES[f"{name}{key}"] = {"build_s": t1 - t0, "compile_s": t2 - t1}
        _CACHE[(name, key)] = fn
    return _CACHE[(name, key)]


def _buf(t: torch.Tensor, shape=None) -> hl.Buffer:
    a = t.detach().expand(shape).contiguous() if shape is not None else t.detach().contiguous()
    return hl.Buffer(a.numpy())


PARTS = 2


class HalideBilateralTaps(torch.autograd.Function):
    @staticmethod
    def forward(ctx, image, direction, step, spatial, neg_a, neg_r, n: int, support: float):  # type: ignore[override]
        assert support == SUPPORT and image.dtype == torch.float32
        b, c, h, w = image.shape
        ins = [_buf(image), _buf(direction, (b, 2, h, w))] + [
            _buf(m, (b, 1, h, w)) for m in (step, spatial, neg_a, neg_r)
        ]
        out = np.empty((b, c + 1, h, w), np.float32)
        _callable("bilateral_fwd", bilateral_forward, c, n)(*ins, hl.Buffer(out))
        ctx.save_for_backward(image, direction, step, spatial, neg_a, neg_r)
        ctx.n = n
        o = torch.from_numpy(out)
        return o[:, :c], o[:, c:]

    @staticmethod
    def backward(ctx, grad_total, grad_norm):  # type: ignore[override]
        image, direction, step, spatial, neg_a, neg_r = ctx.saved_tensors
        b, c, h, w = image.shape
        ins = [_buf(image), _buf(direction, (b, 2, h, w))] + [
            _buf(m, (b, 1, h, w)) for m in (step, spatial, neg_a, neg_r)
        ]
        ins += [_buf(grad_total, (b, c, h, w)), _buf(grad_norm, (b, 1, h, w))]
        out = np.empty((b, c + 5, h, w), np.float32)
        _callable("bilateral_bwd", bilateral_backward, c, ctx.n)(*ins, PARTS, hl.Buffer(out))
        g = torch.from_numpy(out)
        return g[:, :c], g[:, c : c + 2], g[:, c + 2 : c + 3], None, g[:, c + 3 : c + 4], g[:, c + 4 :], None, None


class HalideFlowSmoothingTaps(torch.autograd.Function):
    @staticmethod
    def forward(ctx, image, tangent, sigma, coefficient, steps: int, step_length: float, support: float):  # type: ignore[override]
        assert support == SUPPORT and image.dtype == torch.float32
        b, c, h, w = image.shape
        ins = [_buf(image), _buf(tangent, (b, 2, h, w)), _buf(sigma, (b, 1, h, w)), _buf(coefficient, (b, 1, h, w))]
        out = np.empty((b, c + 1, h, w), np.float32)
        _callable("smoothing_fwd", flow_smoothing_forward, c)(*ins, steps, step_length, hl.Buffer(out))
        ctx.save_for_backward(image, tangent, sigma, coefficient)
        ctx.settings = (steps, step_length)
        o = torch.from_numpy(out)
        return o[:, :c], o[:, c:]

    @staticmethod
    def backward(ctx, grad_total, grad_norm):  # type: ignore[override]
        image, tangent, sigma, coefficient = ctx.saved_tensors
        b, c, h, w = image.shape
        ins = [_buf(image), _buf(tangent, (b, 2, h, w)), _buf(sigma, (b, 1, h, w)), _buf(coefficient, (b, 1, h, w))]
        ins += [_buf(grad_total, (b, c, h, w)), _buf(grad_norm, (b, 1, h, w))]
        out = np.empty((b, c + 1, h, w), np.float32)
        _callable("smoothing_bwd", flow_smoothing_backward, c)(*ins, *ctx.settings, PARTS, hl.Buffer(out))
        g = torch.from_numpy(out)
        return g[:, :c], None, None, g[:, c:], None, None, None


# ----------------------------------------------------------------------------------- benchmark ---


def kernel_loc() -> int:
    """Non-blank, non-comment lines between the kernel markers (docstrings included)."""
    lines = Path(__file__).read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.strip() == "# HALIDE-KERNELS-BEGIN")
    end = next(i for i, line in enumerate(lines) if line.strip() == "# HALIDE-KERNELS-END")
    return sum(1 for line in lines[start + 1 : end] if line.strip() and not line.strip().startswith("#"))


def make_inputs(size: int, batch: int):
    import torch.nn.functional as F
    from skimage import data

    from wise.filters.color import rgb_to_lab
    from wise.filters.gaussian import gaussian_blur
    from wise.filters.structure import edge_tangent_flow, structure_tensor

    rgb = torch.from_numpy(data.astronaut()).permute(2, 0, 1)[None].float() / 255.0
    rgb = F.interpolate(rgb, size=(size, size), mode="bilinear", align_corners=False, antialias=True).clamp(0, 1)
    views = [rgb, rgb.flip(-1), rgb.flip(-2), rgb.transpose(-1, -2)]
    rgb = torch.cat([views[i % 4] for i in range(batch)]).contiguous()
    lab = rgb_to_lab(rgb).contiguous()
    tangent = edge_tangent_flow(gaussian_blur(structure_tensor(lab, 1.0), 2.0)).contiguous()
    return lab, tangent


NUMBA_REVISION = "420e1e9"
"""The last commit whose ``wise.filters.fused`` holds the Numba ``BilateralTaps`` (later ones moved
the bilateral pass to Dr.Jit and the working tree is changing): its four modules are extracted
(``git show``, read only) into a package of their own next to a Numba cache that persists."""


def numba_reference():
    """``(BilateralTaps, FlowSmoothingTaps)`` of the Numba kernels at :data:`NUMBA_REVISION`."""
    import importlib

    root = Path(tempfile.gettempdir()) / f"halide_taps_numba_{NUMBA_REVISION}"
    package = root / "wise_numba_ref"
    if not (package / "dog.py").exists():
        package.mkdir(parents=True, exist_ok=True)
        repo = Path(__file__).resolve().parents[2]
        for name in ("__init__", "bilinear", "bilateral", "dog"):
            text = subprocess.run(
                ["git", "show", f"{NUMBA_REVISION}:src/wise/filters/fused/{name}.py"],
                cwd=repo,
                capture_output=True,
                text=True,
                check=True,
            ).stdout
            (package / f"{name}.py").write_text(text.replace("wise.filters.fused", "wise_numba_ref"))
    sys.path.insert(0, str(root))
    return (
        importlib.import_module("wise_numba_ref.bilateral").BilateralTaps,
        importlib.import_module("wise_numba_ref.dog").FlowSmoothingTaps,
    )


def bilateral_args(image, direction, sigma_d=2.0, sigma_r=5.0, samples=3):
    """As :func:`wise.filters.bilateral.bilateral_pass` prepares them, maps expanded to full size."""
    MIN_SIGMA = 1e-3  # wise.filters.gaussian.MIN_SIGMA

    def _merged_samples_needed(sigma_max):
        return max(1, math.floor((SUPPORT * sigma_max + 1.0) / 2.0))

    def pixel_step(d):
        return 1.0 / torch.maximum(d[:, 0:1].abs(), d[:, 1:2].abs()).clamp_min(1e-6)

    b, _, h, w = image.shape
    s = min(h, w) / 512
    spatial = torch.full((b, 1, h, w), max(sigma_d * s, MIN_SIGMA))
    neg_r = torch.full((b, 1, h, w), -0.5 / max(sigma_r, MIN_SIGMA) ** 2)
    neg_a = -0.5 / spatial.square()
    n = min(samples, _merged_samples_needed(float(spatial.max())))
    step = pixel_step(direction)
    return [image, direction, step, spatial, neg_a, neg_r], n


def smoothing_args(image, tangent, sigma=4.0, max_steps=64):
    """As :func:`wise.filters.dog.flow_smoothing` prepares them, maps expanded to full size."""
    MIN_SIGMA = 1e-3

    def spaced_samples(reach, max_samples, min_spacing=1.0):
        spacing = max(min_spacing, reach / max_samples)
        return spacing, max(1, min(max_samples, math.floor(reach / spacing)))

    b, _, h, w = image.shape
    s = min(h, w) / 512
    sigma_px = torch.full((b, 1, h, w), max(sigma * s, MIN_SIGMA))
    step_length, steps = spaced_samples(SUPPORT * float(sigma_px.max()), max_steps, max(1.0, s))
    return [image, tangent, sigma_px, -0.5 / sigma_px.square()], steps, step_length


def best_of(fn, repeats=5):
    fn()  # warm-up
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times) * 1e3


def run_case(name, numba_fn, halide_fn, tensors, grad_mask, extra, repeats):
    """Outputs and gradients of both, their differences, and timings."""
    torch.manual_seed(0)
    leaves = [t.detach().clone().requires_grad_(g) for t, g in zip(tensors, grad_mask)]
    results = {}
    for engine, fn in (("numba", numba_fn), ("halide", halide_fn)):
        for t in leaves:
            t.grad = None
        total, norm = fn(*leaves, *extra)
        g = torch.Generator().manual_seed(1)
        gt, gn = torch.randn(total.shape, generator=g), torch.randn(norm.shape, generator=g)
        torch.autograd.backward([total, norm], [gt, gn])
        results[engine] = [total.detach().clone(), norm.detach().clone()] + [
            t.grad.clone() for t, m in zip(leaves, grad_mask) if m
        ]
    names = ["total", "norm"] + [f"grad[{i}]" for i, m in enumerate(grad_mask) if m]
    diffs = {
        n: {
            "max_abs_diff": float((a - b).abs().max()),
            "max_abs_ref": float(a.abs().max()),
            # float32 vs float64 positions that land on pixel rows/columns may pick the other cell (slopes jump)
            "frac_diff_over_1e-3_max_ref": float(((a - b).abs() > 1e-3 * a.abs().max()).double().mean()),
        }
        for n, a, b in zip(names, results["numba"], results["halide"])
    }
    timings = {}
    for engine, fn in (("numba", numba_fn), ("halide", halide_fn)):

        def forward():
            with torch.no_grad():
                fn(*tensors, *extra)

        def both():
            for t in leaves:
                t.grad = None
            total, norm = fn(*leaves, *extra)
            torch.autograd.backward([total, norm], [torch.ones_like(total), torch.ones_like(norm)])

        timings[engine] = {"forward_ms": best_of(forward, repeats), "fwd_bwd_ms": best_of(both, repeats)}
    return {"diffs": diffs, "timings": timings}


def aot_probe(workdir: Path) -> dict:
    """Ahead-of-time route: the backward pipeline as a Python extension (needs a C++ compiler and
    Python headers to build), loaded in a fresh process without JIT."""
    import sysconfig

    info = {}
    pipeline, args = flow_smoothing_backward(3)
    t0 = time.perf_counter()
    pipeline.compile_to(
        {
            hl.OutputFileType.python_extension: str(workdir / "lic_bwd.py.cpp"),
            hl.OutputFileType.object: str(workdir / "lic_bwd.o"),
            hl.OutputFileType.c_header: str(workdir / "lic_bwd.h"),
        },
        args,
        "lic_bwd",
        TARGET.without_feature(hl.TargetFeature.JIT).with_feature(hl.TargetFeature.NoRuntime),
    )
    info["halide_compile_to_object_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    runtime = workdir / "runtime.o"
    hl.compile_standalone_runtime(str(runtime), TARGET.without_feature(hl.TargetFeature.JIT))
    info["runtime_object_s"] = time.perf_counter() - t0
    include = Path(hl.install_dir()) / "include"
    ext = workdir / ("lic_bwd" + sysconfig.get_config_var("EXT_SUFFIX"))
    cmd = [
        "g++",
        "-O2",
        "-shared",
        "-fPIC",
        "-std=c++17",
        f"-I{include}",
        f"-I{workdir}",
        f"-I{sysconfig.get_paths()['include']}",
        "-DHALIDE_PYTHON_EXTENSION_MODULE_NAME=lic_bwd",
        str(workdir / "lic_bwd.py.cpp"),
        str(workdir / "lic_bwd.o"),
        str(runtime),
        "-o",
        str(ext),
        "-lpthread",
        "-ldl",
    ]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    info["gxx_build_s"] = time.perf_counter() - t0
    info["gxx_returncode"] = proc.returncode
    if proc.returncode:
        info["gxx_stderr"] = proc.stderr[-1500:]
        return info
    probe = (
        "import time; t=time.perf_counter(); import sys; sys.path.insert(0, %r); import lic_bwd; "
        "print(time.perf_counter()-t); print([n for n in dir(lic_bwd) if not n.startswith('_')])" % str(workdir)
    )
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True)
    info["fresh_process_import"] = {
        "wall_s": time.perf_counter() - t0,
        "stdout": proc.stdout.strip(),
        "stderr": proc.stderr[-800:],
    }
    return info


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", type=Path, help="write the numbers here")
    parser.add_argument("--sizes", default="1024x1,256x8", help="NxB, comma separated")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--no-aot", action="store_true")
    options = parser.parse_args()
    torch.set_num_threads(2)
    report = {"target": str(TARGET), "hl_num_threads": os.environ.get("HL_NUM_THREADS"), "cases": {}}
    BilateralTaps, FlowSmoothingTaps = numba_reference()
    report["numba_revision"] = NUMBA_REVISION

    for spec in options.sizes.split(","):
        size, batch = (int(v) for v in spec.split("x"))
        lab, tangent = make_inputs(size, batch)
        bil, n = bilateral_args(lab, tangent)
        case = run_case(
            "bilateral",
            BilateralTaps.apply,
            HalideBilateralTaps.apply,
            bil,
            [True, True, True, False, True, True],
            [n, SUPPORT],
            options.repeats,
        )
        case["settings"] = {"n": n}
        report["cases"][f"bilateral {size}^2 x{batch}"] = case
        lic, steps, step_length = smoothing_args(lab, tangent)
        case = run_case(
            "flow_smoothing",
            FlowSmoothingTaps.apply,
            HalideFlowSmoothingTaps.apply,
            lic,
            [True, False, False, True],
            [steps, step_length, SUPPORT],
            options.repeats,
        )
        case["settings"] = {"steps": steps, "step_length": step_length}
        report["cases"][f"flow_smoothing {size}^2 x{batch}"] = case
    report["compile_times_first_process"] = dict(COMPILE_TIMES)
    # a second compile of the same pipeline object is a no-op (Pipeline caches its JIT module);
    # a new Pipeline built from the same definitions compiles again
    pipeline, args = flow_smoothing_forward(3)
    t0 = time.perf_counter()
    pipeline.compile_to_callable(args, TARGET)
    t1 = time.perf_counter()
    pipeline.compile_jit(TARGET)
    t2 = time.perf_counter()
    pipeline.compile_jit(TARGET)
    t3 = time.perf_counter()
    report["recompile_in_process"] = {
        "flow_smoothing_forward_rebuilt_compile_to_callable_s": t1 - t0,
        "same_pipeline_compile_jit_first_s": t2 - t1,
        "same_pipeline_compile_jit_again_s": t3 - t2,
    }
    report["kernel_loc"] = kernel_loc()
    if not options.no_aot:
        with tempfile.TemporaryDirectory() as tmp:
            try:
                report["aot_python_extension"] = aot_probe(Path(tmp))
            except Exception as error:  # report, do not fail the benchmark
                report["aot_python_extension"] = {"error": repr(error)[:1500]}

    print(f"{'case':32s} {'engine':7s} {'fwd ms':>9s} {'fwd+bwd ms':>11s}")
    for name, case in report["cases"].items():
        for engine, t in case["timings"].items():
            print(f"{name:32s} {engine:7s} {t['forward_ms']:9.1f} {t['fwd_bwd_ms']:11.1f}")
        for what, d in case["diffs"].items():
            print(
                f"    max|numba-halide| {what:9s} {d['max_abs_diff']:.3e}  (max|numba| {d['max_abs_ref']:.3e}; "
                f"fraction > 1e-3 max|numba|: {d['frac_diff_over_1e-3_max_ref']:.1e})"
            )
    for name, t in report["compile_times_first_process"].items():
        print(f"compile {name:28s} build {t['build_s']:.2f} s  compile_to_callable {t['compile_s']:.2f} s")
    print("recompile:", report["recompile_in_process"])
    print("kernel LOC:", report["kernel_loc"])
    if "aot_python_extension" in report:
        print("AOT:", json.dumps(report["aot_python_extension"], indent=1)[:3000])
    if options.json:
        options.json.write_text(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
