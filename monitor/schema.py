"""What every configuration section shares: the error type, reading the TOML, "did you mean",
and the declarative section parser.

A section is declared once, as a frozen ``msgspec.Struct`` whose fields carry their type,
default and bounds (``Annotated[float, Meta(gt=0)]``; ``Meta(description=...)`` words the
error); :func:`parse_struct` turns the section's TOML table into it, key by key, so every
error names the file's key path and the bad value::

    config error: zenoh.mode = 'router': must be one of ['client', 'peer']
    config error: zenoh.listn = [...]: unknown key (did you mean 'listen'?); expected one of [...]

Every error one pass can find is reported at once: :func:`parse_struct` gathers the errors of
all the keys of a table (unknown ones included), and :class:`Errors` those of sections parsed
one by one (``monitor.config.parse_config``); several come as one :class:`ConfigErrors`, a line
each. A check across keys runs once the keys it reads are valid.

A struct's ``check(self, where, raw)`` (optional) does what types cannot: checks across keys
and defaults that depend on other keys; it returns the struct, replaced where needed.
Sections whose defaults derive from other sections (``monitor.config``) read their tables with
:class:`SectionReader`, which raises the same errors.

msgspec, not pydantic (measured on top of what the daemon imports before it reads its
configuration, 2026-11-25, 2-core Xeon): import 14 ms and 1.4 MB resident against 150 ms and
10.8 MB; ``buoymon check-config`` stays under its 0.3 s target.
"""

from __future__ import annotations

import builtins
import difflib
import math
import tomllib
from pathlib import Path
from types import UnionType
from typing import (Annotated, Any, Callable, Iterable, Literal, Mapping, Sequence, TypeVar, Union,
                    get_args, get_origin)

import msgspec

# longest time span a duration key may give: time is int64 ns, and a span in ns must fit with
# room to add it to a time stamp (1e9 s is about 32 years)
MAX_DURATION_S = 1e9


class ConfigError(ValueError):
    """A configuration value is missing, of the wrong type or out of range."""


class ConfigErrors(ConfigError):
    """Several errors of one document; the message holds one ``config error: ...`` line each."""

    def __init__(self, errors: Sequence[ConfigError]) -> None:
        self.errors = tuple(errors)
        super().__init__("\n".join(str(e) for e in self.errors))


T = TypeVar("T")


class Errors:
    """The errors of parts of a document parsed independently, so one run names them all::

        errors = Errors()
        load = errors.parse(parse_struct, LoadConfig, data.get("load"), "load")  # None if bad
        errors.raise_any()
    """

    def __init__(self) -> None:
        self.found: list[ConfigError] = []

    def add(self, exc: ConfigError) -> None:
        for e in exc.errors if isinstance(exc, ConfigErrors) else (exc,):
            # two sections reading one key (the bridge's and the core's buoy.id) say it once
            if str(e) not in map(str, self.found):
                self.found.append(e)

    def parse(self, fn: Callable[..., T], *args: Any) -> T | None:
        """``fn(*args)``, or None with its errors kept."""
        try:
            return fn(*args)
        except ConfigError as exc:
            self.add(exc)
            return None

    def raise_any(self) -> None:
        """Raise what was found: the one error itself, or all as :class:`ConfigErrors`."""
        if len(self.found) == 1:
            raise self.found[0]
        if self.found:
            raise ConfigErrors(self.found)


def read_toml(path: str | Path) -> dict[str, Any]:
    """The parsed TOML document at ``path``; ConfigError naming the file otherwise."""
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except FileNotFoundError:
        raise ConfigError(f"config error: file {str(path)!r} not found") from None
    except OSError as exc:  # a folder, no permission: the same exit status 2 as a bad file
        raise ConfigError(f"config error: {path}: cannot read ({exc.strerror})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"config error: {path}: not valid TOML: {exc}") from None
    except UnicodeDecodeError:
        raise ConfigError(f"config error: {path}: not valid TOML (not UTF-8 text)") from None


def _show(value: Any) -> str:
    text = repr(value)  # a whole mistyped section can be long: its start says enough
    return text if len(text) <= 80 else text[:77] + "..."


def error(where: str, key: str, value: Any, why: str) -> ConfigError:
    """``config error: <where>.<key> = <value>: <why>``."""
    return ConfigError(f"config error: {where + '.' if where else ''}{key} = {_show(value)}: {why}")


def did_you_mean(name: str, known: Iterable[str]) -> str:
    """`` (did you mean 'x'?)`` with the known name nearest to ``name``, or ""."""
    near = difflib.get_close_matches(name, list(known), n=1)
    return f" (did you mean {near[0]!r}?)" if near else ""


def unknown(where: str, key: str, value: Any, known: Iterable[str], what: str = "key",
            name: str | None = None) -> ConfigError:
    """A key (or section) nobody reads, with the nearest known name: a typo, usually.
    ``name`` is the unknown name when it is the value, not the key (a rule's component)."""
    known = sorted(known)
    why = f"unknown {what}{did_you_mean(key if name is None else name, known)}; " \
          f"expected one of {known}"
    if what == "section":  # its whole table would say nothing more
        return ConfigError(f"config error: [{key}]: {why}")
    return error(where, key, value, why)


def check_keys(where: str, table: Any, known: Iterable[str], what: str = "key"
               ) -> Mapping[str, Any]:
    """``table`` itself, when it is a table holding only ``known`` keys."""
    if not isinstance(table, Mapping):
        raise ConfigError(f"config error: {where} = {_show(table)}: must be a table")
    known = set(known)
    for key in table:
        if key not in known:
            raise unknown(where, key, table[key], known, what)
    return table


# --- declarative sections ---------------------------------------------------------------------

S = TypeVar("S", bound=msgspec.Struct)


def _describe(tp: Any) -> str:
    """What a value of type ``tp`` must be, for the error message."""
    options = [t for t in get_args(tp) if t is not type(None)]
    if get_origin(tp) in (Union, UnionType) and len(options) == 1:  # X | None: TOML has no None
        return _describe(options[0])
    if get_origin(tp) in (Union, UnionType):  # e.g. a number or "auto"
        return " or ".join(_describe(t) for t in options)
    metas = [m for m in get_args(tp)[1:] if isinstance(m, msgspec.Meta)]
    if get_origin(tp) is not None and metas:
        if metas[0].description:
            return metas[0].description
        tp = get_args(tp)[0]
    else:
        metas = []
    m = metas[0] if metas else msgspec.Meta()
    if tp is bool:
        return "true or false"
    if get_origin(tp) is Literal:
        return f"one of {list(get_args(tp))}"
    if tp is str:
        return "a non-empty string" if m.min_length else "a string"
    bounds = " and ".join(f"{op} {v:g}" if isinstance(v, float) else f"{op} {v}" for op, v in (
        (">", m.gt), (">=", m.ge), ("<", m.lt), ("<=", m.le)) if v is not None)
    if tp is int:
        return f"an integer {bounds}".rstrip()
    if tp is float:
        kind = "a number (inf allowed)" if (m.extra or {}).get("nonfinite") else "a finite number"
        return f"{kind} {bounds}".rstrip()
    return f"of type {getattr(tp, '__name__', tp)}"


def _struct_type(tp: Any) -> type[msgspec.Struct] | None:
    """The Struct in ``tp`` (``X`` or ``X | None``), or None."""
    for t in (tp, *get_args(tp)):
        if isinstance(t, type) and issubclass(t, msgspec.Struct):
            return t
    return None


def convert(where: str, key: str, value: Any, tp: Any) -> Any:
    """``value`` as type ``tp`` (msgspec conversion with ``tp``'s bounds); floats must be finite
    (+-inf allowed when its ``Meta`` has ``extra={"nonfinite": True}``, NaN never).
    ConfigError naming key and value."""
    try:
        out = msgspec.convert(value, tp)
    except msgspec.ValidationError:
        raise error(where, key, value, f"must be {_describe(tp)}") from None
    if isinstance(out, float) and (math.isnan(out) or math.isinf(out) and not any(
            isinstance(m, msgspec.Meta) and (m.extra or {}).get("nonfinite")
            for m in get_args(tp)[1:])):
        raise error(where, key, value, f"must be {_describe(tp)}")
    return out


def parse_struct(cls: type[S], raw: Any, where: str) -> S:
    """The section ``cls`` from its TOML table ``raw`` (None or absent keys: the defaults).

    Every key is converted by :func:`convert` against its declared type; a nested Struct is
    parsed the same way under ``where.key``. Then ``cls.check(obj, where, raw)`` if it exists.
    """
    fields = {f.encode_name: f for f in msgspec.structs.fields(cls)}  # the TOML key names
    table = {} if raw is None else raw
    if not isinstance(table, Mapping):
        raise ConfigError(f"config error: {where} = {_show(table)}: must be a table")
    errors = Errors()  # every key's error, then check() once they all hold
    values: dict[str, Any] = {}
    for key, value in table.items():
        if key not in fields:
            errors.add(unknown(where, key, value, fields))
            continue
        tp = fields[key].type
        nested = _struct_type(tp)
        try:
            values[fields[key].name] = (parse_struct(nested, value, f"{where}.{key}")
                                        if nested is not None and isinstance(value, Mapping)
                                        else convert(where, key, value, tp))
        except ConfigError as exc:
            errors.add(exc)
    for key, f in fields.items():
        if f.required and key not in table:
            errors.add(ConfigError(f"config error: {where}.{key} is missing"))
    errors.raise_any()
    obj = cls(**values)
    check = getattr(obj, "check", None)
    return check(where, table) if check is not None else obj


# --- sections with derived defaults -----------------------------------------------------------

class SectionReader:  # its methods str, float, bool shadow the builtins: builtins.* below
    """Typed, path-aware access to one TOML table; unknown keys are errors.

    ``r = SectionReader(table, "alerts.rule[2]")``; ``r.float("threshold", gt=0)``;
    ``r.done()`` raises if the table holds a key nobody read (a typo, usually).

    With ``gather=True`` a bad value does not stop the reading: its error is kept, the getter
    returns a stand-in (the default, or a neutral value) and ``done()`` raises every error of
    the table at once, so one run names them all. A check across keys asks :meth:`ok` first
    (a stand-in is no value to check against) and reports through :meth:`reject`; the caller
    must reach ``done()`` or raise ``errors`` itself, so no stand-in is ever used.
    """

    def __init__(self, table: Any, path: str, gather: builtins.bool = False) -> None:
        if not isinstance(table, Mapping):
            raise ConfigError(f"config error: {path} = {_show(table)}: must be a table")
        self.table = table
        self.path = path
        self.gather = gather
        self.errors = Errors()
        self._failed: set[str] = set()
        self._seen: set[str] = set()
        self._known: set[str] = set()

    def error(self, key: str, value: Any, why: str) -> ConfigError:
        return error(self.path, key, value, why)

    def reject(self, key: str, value: Any, why: str) -> None:
        """The error of ``key``: kept when gathering, raised otherwise."""
        self._keep(key, self.error(key, value, why))

    def _keep(self, key: str, exc: ConfigError) -> None:
        if not self.gather:
            raise exc
        self.errors.add(exc)
        self._failed.add(key)

    def ok(self, *keys: str) -> builtins.bool:
        """No error was kept for any of ``keys`` (nor for the table, with no keys given)."""
        return not (self._failed.intersection(keys) if keys else self._failed)

    def part(self, fn: Callable[..., T], table: Any, path: str, *args: Any) -> T | None:
        """``fn(SectionReader(table, path), *args)`` for a table inside this one, read the same
        way; when gathering, its errors are kept here and the result is None."""
        try:
            return fn(SectionReader(table, path, self.gather), *args)
        except ConfigError as exc:
            self._keep(path, exc)
            return None

    def has(self, key: str) -> bool:
        self._known.add(key)
        return key in self.table

    def raw(self, key: str, default: Any = None) -> Any:
        self._seen.add(key)
        return self.table.get(key, default)

    def _value(self, key: str, default: Any) -> Any:
        """The key's value, or ``default``; None: the key is required."""
        self._seen.add(key)
        if key not in self.table and default is None:
            raise ConfigError(f"config error: {self.path + '.' if self.path else ''}{key} "
                              "is missing")
        return self.table.get(key, default)

    def checked(self, key: str, read: Callable[[], T], stand_in: T) -> T:
        """``read()``; when gathering, ``stand_in`` if it raises (its error kept)."""
        try:
            return read()
        except ConfigError as exc:
            self._keep(key, exc)
            return stand_in

    def str(self, key: str, default: str | None = None, choices: Sequence[str] | None = None
            ) -> str:
        def read() -> builtins.str:
            value = convert(self.path, key, self._value(key, default), builtins.str)
            if choices is not None and value not in choices:
                raise self.error(key, value, f"must be one of {list(choices)}")
            return value
        return self.checked(key, read, default if default is not None else
                          choices[0] if choices else "")

    def float(self, key: builtins.str, default: float | None = None, *,
              gt: float | None = None, ge: float | None = None, le: float | None = None,
              allow_inf: bool = False) -> float:
        bounds = {k: v for k, v in (("gt", gt), ("ge", ge), ("le", le)) if v is not None}
        # msgspec's stubs list the bound combinations one by one; any of them is valid here
        meta = msgspec.Meta(**bounds, extra={"nonfinite": allow_inf})  # type: ignore[call-overload]
        return self.checked(key, lambda: convert(self.path, key, self._value(key, default),
                                               Annotated[float, meta]),
                          default if default is not None else 1.0)

    def bool(self, key: builtins.str, default: bool | None = None) -> bool:
        return self.checked(key, lambda: convert(self.path, key, self._value(key, default), bool),
                          bool(default))

    def floats(self, key: builtins.str, default: Sequence[builtins.float] | None = None, *,
               increasing: builtins.bool = False, min_len: int = 1
               ) -> tuple[builtins.float, ...]:
        def read() -> tuple[builtins.float, ...]:
            value = self._value(key, default)
            if not isinstance(value, (list, tuple)) or len(value) < min_len or any(
                isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v)
                for v in value
            ):
                raise self.error(key, value, f"must be a list of at least {min_len} finite "
                                 "numbers")
            out = tuple(builtins.float(v) for v in value)
            if increasing and any(b <= a for a, b in zip(out, out[1:])):
                raise self.error(key, value, "must be strictly increasing")
            return out
        return self.checked(key, read, tuple(default) if default is not None else
                          tuple(builtins.float(i + 1) for i in range(min_len)))

    def table_list(self, key: builtins.str) -> list[Mapping[builtins.str, Any]]:
        value = self.raw(key, [])
        if not isinstance(value, list):
            raise self.error(key, value, "must be an array of tables ([[...]])")
        return value

    def done(self) -> None:
        """Raise the errors kept (when gathering) and those of the keys nobody read, each
        naming the nearest one that is read."""
        errors = Errors()
        for exc in self.errors.found:
            errors.add(exc)
        for key in self.table:
            if key not in self._seen:
                errors.add(unknown(self.path, key, self.table[key], self._seen | self._known))
        errors.raise_any()
