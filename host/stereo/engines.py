"""The engine table: one row per matching engine, keyed by the protocol's ``algorithm`` value.

A row names the engine, its parameter class, how those parameters come from a device configuration
(``ConfigField`` rows, data), the matcher that runs it and its warm-up. The device pipeline, replay,
``stereocam rematch`` and the benches select engines here only; a new engine is one module, one
``register`` call (its row) and its protocol rows (the ``algorithm`` value, any new parameters).

    from stereocam.stereo.engines import engine_for, match
    disp = match(left, right, SGMParams(num_disparities=128))  # the row whose params class it is
    matcher = engine_for(cfg["algorithm"]).matcher(left.shape, params_from_config(cfg))
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from stereocam.protocol.errors import ConfigError
from stereocam.protocol.params import BY_NAME, Algorithm

from . import config_map
from .config_map import ConfigField
from .matcher import Matcher, bm_warm_up, check_pair
from .params import BM_CONFIG, MatchParams
from .sgm_matcher import SGMMatcher, sgm_warm_up
from .sgm_params import SGM_CONFIG, SGMParams


class StereoMatcher(Protocol):
    """What an engine's matcher is: built for one (shape, params), reused frame after frame."""

    shape: tuple[int, int]
    params: Any

    def match(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """Disparity (int16, disparity * 16, invalid = protocol ``invalid_disparity(min_disparity)``)."""
        ...


@dataclass(frozen=True)
class Engine:
    """One matching engine."""

    algorithm: int  # the protocol's ``algorithm`` value that selects it
    name: str  # short name for people and command lines ("bm", "sgm")
    params: type  # its parameter dataclass
    config: tuple[ConfigField, ...]  # device configuration key -> parameter field
    matcher: Callable[[tuple[int, int], Any], StereoMatcher]  # (shape, params) -> matcher
    warm_up: Callable[[], None]  # compiles (or loads) its kernels once per process

    def params_from_config(self, cfg: Mapping[str, int]) -> Any:
        """This engine's parameters from a device configuration."""
        return config_map.params_from_config(self.params, self.config, cfg)


ENGINES: dict[int, Engine] = {}
_lock = threading.Lock()


def register(engine: Engine) -> Engine:
    """Add ``engine`` to the table (ConfigError when its algorithm value, name or parameter
    class is taken)."""
    with _lock:
        for e in ENGINES.values():
            if engine.algorithm == e.algorithm or engine.name == e.name or engine.params is e.params:
                raise ConfigError(f"engine {engine.name!r} (algorithm {engine.algorithm}) clashes with {e.name!r}")
        ENGINES[engine.algorithm] = engine
    return engine


def unregister(algorithm: int) -> None:
    """Remove the engine of ``algorithm`` (for engines registered at run time)."""
    with _lock:
        ENGINES.pop(algorithm, None)


register(Engine(Algorithm.BLOCK_MATCHING, "bm", MatchParams, BM_CONFIG, Matcher, bm_warm_up))
register(Engine(Algorithm.SEMI_GLOBAL, "sgm", SGMParams, SGM_CONFIG, SGMMatcher, sgm_warm_up))


def engine_for(algorithm: int) -> Engine:
    """The engine of an ``algorithm`` value (ConfigError when there is none)."""
    engine = ENGINES.get(algorithm)
    if engine is None:
        raise ConfigError(f"no matching engine for algorithm {algorithm}; known: "
                          + ", ".join(f"{e.algorithm} ({e.name})" for e in ENGINES.values()))
    return engine


def engine_named(name: str) -> Engine:
    """The engine called ``name`` (ConfigError when there is none)."""
    for engine in ENGINES.values():
        if engine.name == name:
            return engine
    raise ConfigError(f"unknown algorithm {name!r}; known: {', '.join(names())}")


def matching_names() -> list[str]:
    """The configuration keys matching reads, in the protocol's order: ``algorithm``, every
    engine's and the post-processing chain's (the others, size, rate, exposure..., make the frames)."""
    from .post.params import POST_CONFIG

    used = {"algorithm"} | {f.key for e in ENGINES.values() for f in e.config} | {f.key for f in POST_CONFIG}
    return [name for name in BY_NAME if name in used]


def names() -> list[str]:
    """The engines' names, in algorithm order."""
    return [ENGINES[a].name for a in sorted(ENGINES)]


def engine_of(params: object) -> Engine:
    """The engine whose parameter class ``params`` is (ConfigError when none)."""
    for engine in ENGINES.values():
        if type(params) is engine.params:
            return engine
    raise ConfigError(f"params must be one of {', '.join(e.params.__name__ for e in ENGINES.values())}, "
                      f"got {type(params).__name__}")


def selected(cfg: Mapping[str, int]) -> Engine:
    """The engine a device configuration selects (one without ``algorithm``, recorded before 1.2,
    does block matching)."""
    return engine_for(cfg.get("algorithm", Algorithm.BLOCK_MATCHING))


def params_from_config(cfg: Mapping[str, int]) -> Any:
    """The selected engine's parameters from a device configuration."""
    return selected(cfg).params_from_config(cfg)


def matcher_for(cfg: Mapping[str, int], shape: tuple[int, int],
                current: StereoMatcher | None = None) -> StereoMatcher:
    """``current`` when it already matches (cfg, shape), else a new matcher of the selected engine."""
    engine = selected(cfg)
    params = engine.params_from_config(cfg)
    if current is not None and current.params == params and tuple(current.shape) == tuple(shape):
        return current
    return engine.matcher((int(shape[0]), int(shape[1])), params)


_cache: dict[tuple, StereoMatcher] = {}
_cache_lock = threading.Lock()
CACHED_MATCHERS = 8


def match(left: np.ndarray, right: np.ndarray, params: object = MatchParams()) -> np.ndarray:
    """Match a rectified grey pair with the engine of ``params`` (a cached matcher per shape and params)."""
    check_pair(left, right)
    engine = engine_of(params)
    key = (left.shape, params)
    with _cache_lock:
        m = _cache.get(key)
        if m is None:
            if len(_cache) >= CACHED_MATCHERS:
                _cache.pop(next(iter(_cache)))
            m = _cache[key] = engine.matcher(left.shape, params)
    return m.match(left, right)


def warm_up() -> float:
    """Compile (or load from numba's disk cache) every engine's kernels; the seconds spent."""
    t0 = time.perf_counter()
    for engine in list(ENGINES.values()):
        engine.warm_up()
    return time.perf_counter() - t0
