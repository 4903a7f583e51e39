"""Compiled loops (numba) for the arithmetic numpy cannot batch (spec §11.3, §11.4.3): each is compiled on its
first call and its machine code cached on disk beside the module, so importing a module that holds one costs
nothing and numba is loaded only by the work that runs it."""

from __future__ import annotations

import functools
from typing import Callable

Loop = Callable[..., None]


def compiled_loop(*signatures: str) -> Callable[[Loop], Loop]:
    """Decorator: the function compiled by numba as ``njit(list(signatures), cache=True, nogil=True)`` (one
    machine-code version per signature, e.g. per output type) when first called (numba is imported then),
    the compiled loop called from then on."""

    def wrap(py_func: Loop) -> Loop:
        loop: Loop | None = None

        @functools.wraps(py_func)
        def call(*args: object) -> None:
            nonlocal loop
            if loop is None:
                from numba import njit

                loop = njit(list(signatures), cache=True, nogil=True)(py_func)
            loop(*args)

        return call

    return wrap
