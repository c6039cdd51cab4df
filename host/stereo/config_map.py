"""How an engine's parameters come from a device configuration, as data: one ``ConfigField`` per
device configuration key (protocol/params.py) naming the engine parameter it sets and the unit or
value conversion between them. The same rows check direct API users' parameters against the
protocol's own rules, so every limit is written once, in the protocol."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

from stereocam.protocol.config_rules import CROSS_RULES
from stereocam.protocol.errors import ConfigError
from stereocam.protocol.params import BY_NAME, VALUE_NAMES


class Transform(Protocol):
    """A declared conversion between a configuration value (int32) and an engine parameter."""

    def to_param(self, value: int) -> Any: ...

    def to_config(self, value: Any) -> int: ...


@dataclass(frozen=True)
class Same:
    """The engine parameter is the configuration value itself (same unit)."""

    def to_param(self, value: int) -> int:
        return int(value)

    def to_config(self, value: Any) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"must be an int, got {value!r}")
        return value


@dataclass(frozen=True)
class ValueName:
    """An enumerated configuration value that the engine takes by its protocol name
    (``VALUE_NAMES[key]``, e.g. pre_filter_type 1 <-> "normalized")."""

    key: str

    def to_param(self, value: int) -> str:
        return VALUE_NAMES[self.key][value]

    def to_config(self, value: Any) -> int:
        names = VALUE_NAMES[self.key]
        for code, name in names.items():
            if name == value:
                return int(code)
        raise ConfigError(f"must be one of {tuple(names.values())}, got {value!r}")


SAME = Same()


@dataclass(frozen=True)
class ConfigField:
    """Device configuration key ``key`` sets engine parameter ``param`` through ``transform``.

    ``protocol_limits``: the parameter's limits are the protocol's (checked with its rule); False
    where the engine accepts a wider domain than the wire allows (its own check then applies)."""

    key: str
    param: str = ""  # "" : the same name as the key
    transform: Transform = SAME
    protocol_limits: bool = True

    @property
    def field(self) -> str:
        return self.param or self.key


P = TypeVar("P")


def params_from_config(cls: type[P], fmap: tuple[ConfigField, ...], cfg: Mapping[str, int]) -> P:
    """``cls`` built from the configuration keys ``fmap`` lists (other keys are not read)."""
    return cls(**{f.field: f.transform.to_param(cfg[f.key]) for f in fmap})


def config_of(params: object, fmap: tuple[ConfigField, ...]) -> dict[str, int]:
    """The device configuration values ``params`` stands for (ConfigError for a value that has none)."""
    out = {}
    for f in fmap:
        try:
            out[f.key] = f.transform.to_config(getattr(params, f.field))
        except ConfigError as exc:
            raise ConfigError(f"{f.field} {exc}") from None
    return out


def check_params(params: object, fmap: tuple[ConfigField, ...]) -> dict[str, int]:
    """ConfigError (a ValueError) naming the first field of ``params`` the protocol's parameter
    table refuses; else the configuration values ``params`` stands for."""
    cfg = config_of(params, fmap)
    for f in fmap:
        if f.protocol_limits:
            why = BY_NAME[f.key].check(cfg[f.key])
            if why:
                raise ConfigError(why if f.field == f.key else f"{f.field}: {why}")
    return cfg


def check_rule(name: str, config: Mapping[str, int]) -> None:
    """ConfigError with the reason when ``config`` breaks the protocol's cross rule ``name`` (SPEC §5.2)."""
    rule = next(r for r in CROSS_RULES if r.name == name)
    if rule.violated(config):
        raise ConfigError(rule.why(config))
