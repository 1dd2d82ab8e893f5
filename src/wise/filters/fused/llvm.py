"""Report whether the Dr.Jit kernels can run here: ``python -m wise.filters.fused.llvm``.

Prints the ``libLLVM`` found, whether Dr.Jit's CPU backend starts with it, and the CPU it compiles
for; exits with 1 when it does not start (``make install`` then installs the library with the
system's package manager where it can, or says how).
"""

from __future__ import annotations

import os
import sys

from wise.filters.fused._drjit import LIBLLVM_VARIABLE, drjit_installed, find_libllvm, llvm_backend
from wise.filters.fused._target import current


def main() -> int:
    if not drjit_installed():
        print("Dr.Jit is not installed: `pip install drjit`", file=sys.stderr)
        return 1
    chosen = os.environ.get(LIBLLVM_VARIABLE) or find_libllvm()
    working = llvm_backend()
    print(f"LLVM for the fast CPU kernels: {chosen or 'none found'} ({'works' if working else 'does not work'})")
    target = current() if working else None
    if target is not None:
        gathers = "hardware" if target.hardware_gathers else "scalar loads"
        print(f"compiled for: {target.cpu}, {target.vector_width} lanes, gathers as {gathers}")
    return 0 if working else 1


if __name__ == "__main__":
    sys.exit(main())
