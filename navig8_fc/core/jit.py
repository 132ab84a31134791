"""numba's njit with an on-disk cache that also knows the kernels it calls in other modules.

numba keys a cached kernel on its own source file (its timestamp and size) and bytecode only: a kernel that
calls a kernel of another module has the callee's machine code compiled into it, and keeps running that old
code after the callee's module changes, until its own file changes (numba issue #6845). `njit_cached(deps)`
adds a digest of the dependency modules to the cache key: the bytecode, constants and names of each numba
kernel in them, their numeric module constants and the slots of their vector layouts (layout.Slots; numba
freezes both into compiled code). Changing any of these recompiles the caller. No file is read (the core does no
I/O): the digest comes from the loaded modules.

A kernel called from another kernel is compiled for its arguments' types without their literal values: numba would
otherwise compile a callee once per constant a caller passes (`gauss_solve_inplace(aug, 5)`, `dynamics(..., True)`
and `(..., False)`: each a compilation of its own and of every kernel it calls), and machine code does not depend on
it (LLVM still sees the constant where it inlines the call; without fastmath it keeps every float operation, so the
results are the same bits).
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from types import CodeType, ModuleType
from typing import Any

from numba import njit
from numba.core import types
from numba.core.caching import FunctionCache
from numba.core.dispatcher import Dispatcher

from navig8_fc.core.layout import Slots

__all__ = ["module_digest", "njit_cached"]


def _code_digest(code: CodeType, h: Any) -> None:
    h.update(code.co_code)
    h.update(repr(code.co_names).encode())
    for c in code.co_consts:
        if isinstance(c, CodeType):
            _code_digest(c, h)
        elif isinstance(c, frozenset):
            h.update(repr(sorted(map(repr, c))).encode())  # set order varies with the hash seed
        else:
            h.update(repr(c).encode())


def module_digest(module: ModuleType) -> str:
    """SHA-256 over a module's numba kernels (bytecode, constants, names), numeric module constants and layouts."""
    h = hashlib.sha256()
    for name, value in sorted(vars(module).items()):
        if isinstance(value, Dispatcher):
            h.update(name.encode())
            _code_digest(value.py_func.__code__, h)
        elif isinstance(value, (bool, int, float)) and not name.startswith("__"):
            h.update(f"{name}={value!r}".encode())
        elif isinstance(value, type) and issubclass(value, Slots) and value is not Slots:
            h.update(f"{name}={[(m.name, int(m)) for m in value]!r}".encode())
    return h.hexdigest()


class _DependentCache(FunctionCache):
    """numba's function cache with the dependencies' digest in every index key."""

    def __init__(self, py_func: Callable[..., Any], digest: str) -> None:
        super().__init__(py_func)
        self._digest = digest

    def _index_key(self, sig: Any, codegen: Any) -> tuple[Any, ...]:
        return (*super()._index_key(sig, codegen), self._digest)


def _unliteral_calls(disp: Dispatcher) -> None:
    """Calls from other kernels type this kernel's arguments without their literal values (module docstring)."""
    resolve = disp.get_call_template

    def get_call_template(args: tuple[Any, ...], kws: dict[str, Any]) -> Any:
        return resolve(tuple(types.unliteral(a) for a in args), {k: types.unliteral(v) for k, v in kws.items()})

    disp.get_call_template = get_call_template


def njit_cached(*depends_on: ModuleType) -> Callable[[Callable[..., Any]], Dispatcher]:
    """numba.njit(cache=True) for a kernel that calls the kernels of the modules `depends_on` (list the modules
    of every kernel reached, directly or not); other kernels call it with their arguments' types, not their literal
    values (module docstring)."""
    digest = hashlib.sha256("".join(module_digest(m) for m in depends_on).encode()).hexdigest()

    def decorate(fn: Callable[..., Any]) -> Dispatcher:
        disp = njit(cache=True)(fn)
        if not isinstance(disp, Dispatcher):  # NUMBA_DISABLE_JIT=1: the plain function, for debugging
            return disp
        disp._cache = _DependentCache(fn, digest)  # replaces the FunctionCache enable_caching() installed
        _unliteral_calls(disp)
        return disp

    return decorate
