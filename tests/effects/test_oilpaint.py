import math

import pytest
import torch
import torch.nn.functional as F

from wise.effects import create
from wise.effects import oilpaint as oil
from wise.effects.base import RenderContext
from wise.filters.gaussian import SUPPORT


def _diagonal_flow(size: int) -> torch.Tensor:
    tangent = torch.tensor([1.0, 1.0]) / math.sqrt(2.0)
    return tangent.view(1, 2, 1, 1).expand(1, 2, size, size).contiguous()


def _texture(effect: oil.OilPaint, size: int, scale: float, stroke: float, brush: float) -> torch.Tensor:
    values = (torch.tensor(stroke).view(1, 1, 1, 1), torch.tensor(brush).view(1, 1, 1, 1))
    return effect.paint_height(_diagonal_flow(size), *values, RenderContext(scale=scale))


def test_longest_stroke_is_sampled_every_bristle_cell() -> None:
    longest = oil.OilPaint().spec("stroke_length").max
    assert SUPPORT * longest / oil.MAX_STROKE_STEPS <= oil.BRISTLE_CELL


@pytest.mark.parametrize("stroke, brush", [(3.0, 0.5), (12.0, 1.5)])
def test_brush_texture_is_the_same_at_four_times_the_resolution(stroke: float, brush: float) -> None:
    effect = create("oilpaint")
    low = _texture(effect, 96, 1.0, stroke, brush)
    high = F.avg_pool2d(_texture(effect, 384, 4.0, stroke, brush), 4)
    inner = (slice(None), slice(None), slice(16, -16), slice(16, -16))
    low, high = low[inner].flatten(), high[inner].flatten()
    correlation = torch.corrcoef(torch.stack([low, high]))[0, 1]
    assert correlation > 0.8
    assert 0.7 < float(high.std() / low.std()) < 1.3


@pytest.mark.parametrize("stroke, brush", [(3.0, 0.5), (8.0, 1.0), (12.0, 1.5)])
def test_strokes_stay_continuous_at_high_resolution(stroke: float, brush: float) -> None:
    """Strokes drawn along the diagonal vary far less along it than across it (no dashes)."""
    texture = _texture(create("oilpaint"), 384, 4.0, stroke, brush)[0, 0, 32:-32, 32:-32]
    lag = 4  # one reference pixel
    along = (texture[lag:, lag:] - texture[:-lag, :-lag]).std()
    across = (texture[lag:, :-lag] - texture[:-lag, lag:]).std()
    assert float(along / across) < 0.4
