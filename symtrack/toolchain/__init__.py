"""The compile-and-cache API (layer 4): every compiled library and program of symtrack is built
through :func:`build` (:mod:`symtrack.toolchain.cache`)."""

from .cache import (
    OPT_LEVEL_ENV,
    TUNED_OPT_LEVEL_ENV,
    BuildSpec,
    Built,
    LockBusy,
    build,
    builds,
    cache_root,
    casadi_tag,
    compiled_required,
    compiler,
    digest,
    file_lock,
    find_compiler,
    native_cflags,
    opt_level,
    require_compiler,
    set_require_compiled,
)

__all__ = ["OPT_LEVEL_ENV", "TUNED_OPT_LEVEL_ENV", "BuildSpec", "Built", "LockBusy", "build", "builds", "cache_root",
           "casadi_tag",
           "compiled_required", "compiler", "digest", "file_lock", "find_compiler", "native_cflags", "opt_level",
           "require_compiler", "set_require_compiled"]
