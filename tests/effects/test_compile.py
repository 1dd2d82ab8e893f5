import pytest

from wise.effects import compile as kernels


def test_compiles_float32_by_default(capsys: pytest.CaptureFixture[str]) -> None:
    assert kernels.main([]) == 0
    printed = capsys.readouterr().out
    assert "compiling the CPU kernels of every effect for float32" in printed
    assert "kernels compiled for float32 in" in printed


def test_refuses_an_unknown_dtype(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as stopped:
        kernels.main(["float16"])
    assert stopped.value.code == 2
    assert "unknown dtype 'float16'; use float32 or float64" in capsys.readouterr().err
