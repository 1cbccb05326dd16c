"""The YAML configuration: load, validate every key, and freeze into a `Config`.

Validation is strict: unknown keys, wrong types and out-of-range values are errors that name the
key and say why (`ConfigError`, exit 78 in the CLIs). Only `yaml.safe_load` is used, and alias
expansion is bounded, so no input can execute code or blow up memory.
"""
from __future__ import annotations

import dataclasses
import difflib
import logging
import math
import stat
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import yaml

from .baseline_rls import BurckhardtRLSOptions
from .estimator import LugreTROptions
from .frontend import FrontEndOptions
from .input_names import OPTIONAL_INPUTS, REQUIRED_INPUTS
from .vehicle import VehicleParams

ESTIMATOR_KINDS = ("lugre-tr", "burckhardt-rls")
MAX_CONFIG_BYTES = 1 << 20
MAX_YAML_NODES = 20_000


class ConfigError(Exception):
    """A config (or a DBC it names) that cannot be used; the message names the problem."""


def package_data_path(name: str) -> Path:
    return Path(__file__).resolve().parent / "data" / name


def default_config_path() -> Path:
    return package_data_path("frictiond.yaml")


@dataclass(frozen=True, slots=True)
class CanConfig:
    interface: str = "socketcan"
    channel: str = "vcan0"
    dbc: tuple[Path, ...] = ()
    dbc_strict: bool = True
    output_dbc: Path = field(default_factory=lambda: package_data_path("frictiond.dbc"))
    bitrate: int | None = None


@dataclass(frozen=True, slots=True)
class SignalSource:
    """Where one canonical input comes from, and how to bring it to SI units."""

    message: str
    signal: str
    unit: str | None = None      # overrides the DBC's unit (e.g. a unitless pressure signal)
    scale: float = 1.0           # applied to the DBC's physical value before unit conversion
    offset: float = 0.0


@dataclass(frozen=True, slots=True)
class EstimatorConfig:
    kind: str = "lugre-tr"
    lugre_tr: LugreTROptions = field(default_factory=LugreTROptions)
    burckhardt_rls: BurckhardtRLSOptions = field(default_factory=BurckhardtRLSOptions)


@dataclass(frozen=True, slots=True)
class OutputConfig:
    wheel_divider: int = 1                       # FRICTION_WHEEL frames every N estimator updates
    estimate_log: Path | None = None             # optional log of everything sent (.log/.blf/.asc)
    estimate_log_max_bytes: int = 50_000_000     # rotate beyond this size
    estimate_log_backups: int = 5


@dataclass(frozen=True, slots=True)
class DaemonConfig:
    state_file: Path | None = None               # None: no persisted state
    state_interval: float = 5.0                  # s between state-file writes
    max_update_rate: float = 250.0               # Hz; a flooding node cannot drive more updates
    reconnect_max_backoff: float = 5.0           # s
    status_interval: float = 1.0                 # s between systemd STATUS= updates


@dataclass(frozen=True, slots=True)
class Config:
    path: Path | None
    can: CanConfig
    vehicle: VehicleParams
    frontend: FrontEndOptions
    estimator: EstimatorConfig
    output: OutputConfig
    daemon: DaemonConfig
    signals: Mapping[str, SignalSource]


# ---------------------------------------------------------------------------------------------
# Numeric sanity of sections whose dataclasses live elsewhere: key -> (low, high, low inclusive)
_VEHICLE_RANGES = {
    "mass": (1.0, 1e5, False),
    "cg_to_front_axle": (0.0, 20.0, False),
    "cg_to_rear_axle": (0.0, 20.0, False),
    "cg_height": (0.0, 5.0, False),
    "track_front": (0.0, 10.0, False),
    "track_rear": (0.0, 10.0, False),
    "wheel_radius": (0.05, 3.0, True),
    "wheel_inertia": (0.0, 100.0, False),
    "brake_gain_front": (0.0, 1e4, False),
    "brake_gain_rear": (0.0, 1e4, False),
    "brake_pushout_pressure": (0.0, 50.0, True),
    "drag_area_coefficient": (0.0, 10.0, True),
    "rolling_resistance": (0.0, 1e4, True),
    "drag_area_doubt": (0.0, 10.0, True),
    "wind_doubt": (0.0, 50.0, True),
}
# A config that does not give the car's air drag: the middle of what cars have (½ρC_dA 0 for a
# simulator without air, up to 0.7 kg/m for a van) and that middle again as its doubt.
UNKNOWN_DRAG_AREA = 0.35


def _check_range(key: str, value: float, low: float, high: float, low_inclusive: bool) -> None:
    if not math.isfinite(value):
        raise ConfigError(f"{key}: must be a finite number, got {value!r}")
    if value < low or (value == low and not low_inclusive) or value > high:
        bound = "≥" if low_inclusive else ">"
        raise ConfigError(f"{key}: {value!r} is out of range (must be {bound} {low:g} and ≤ {high:g})")


def _type_name(tp: Any) -> str:
    return getattr(tp, "__name__", str(tp))


def _coerce(key: str, value: Any, tp: Any, base: Path) -> Any:
    """Check one scalar against its annotated type; paths resolve against the config's folder."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if value is None:
            return None
        return _coerce(key, value, args[0], base)
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{key}: must be true or false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{key}: must be an integer, got {value!r}")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{key}: must be a number, got {value!r}")
        try:
            value = float(value)
        except OverflowError:   # a YAML integer of hundreds of digits
            raise ConfigError(f"{key}: must be a finite number, got an integer of {len(str(value))} digits") from None
        if not math.isfinite(value):
            raise ConfigError(f"{key}: must be a finite number, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str) or not value:
            raise ConfigError(f"{key}: must be a non-empty string, got {value!r}")
        return value
    if tp is Path:
        if not isinstance(value, str) or not value:
            raise ConfigError(f"{key}: must be a file path, got {value!r}")
        path = Path(value).expanduser()
        return path if path.is_absolute() else (base / path)
    if origin is tuple:  # tuple[float, ...] tuning vectors
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{key}: must be a list, got {value!r}")
        (item_tp, *_rest) = typing.get_args(tp)
        return tuple(_coerce(f"{key}[{i}]", v, item_tp, base) for i, v in enumerate(value))
    raise ConfigError(f"{key}: unsupported setting type {_type_name(tp)}")


def _build_section(cls: type, data: Any, prefix: str, base: Path, ranges: Mapping | None = None) -> Any:
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"{prefix}: must be a mapping of settings, got {type(data).__name__}")
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls) if f.init}
    kwargs = {}
    for key, value in data.items():
        full = f"{prefix}.{key}"
        if not isinstance(key, str) or key not in names:
            close = difflib.get_close_matches(str(key), names, n=3, cutoff=0.6)
            known = ", ".join(sorted(names))
            if close:
                hint = f"did you mean {' or '.join(close)}?"
            elif len(known) <= 600:
                hint = f"known: {known}"
            else:   # (a list of fifty settings would bury the message)
                hint = f"{len(names)} settings, the fields of {cls.__module__}.{cls.__qualname__}"
            raise ConfigError(f"{full}: unknown setting ({hint})")
        tp = hints[key]
        if dataclasses.is_dataclass(tp):
            kwargs[key] = _build_section(tp, value, full, base)
            continue
        kwargs[key] = _coerce(full, value, tp, base)
        if ranges and key in ranges and kwargs[key] is not None:
            _check_range(full, kwargs[key], *ranges[key])
    try:
        obj = cls(**kwargs)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{prefix}: {exc}") from None
    validate = getattr(obj, "validate", None)
    if callable(validate):
        try:
            validate()
        except ValueError as exc:
            raise ConfigError(f"{prefix}.{exc}") from None
    return obj


def _build_can(data: Any, base: Path) -> CanConfig:
    if not isinstance(data, dict):
        raise ConfigError(f"can: must be a mapping of settings, got {type(data).__name__}")
    data = dict(data)
    dbc = data.pop("dbc", None)
    if dbc is None:
        raise ConfigError("can.dbc: missing (the DBC file(s) describing the input frames)")
    if isinstance(dbc, str):
        dbc = [dbc]
    if not isinstance(dbc, list) or not dbc or not all(isinstance(d, str) and d for d in dbc):
        raise ConfigError(f"can.dbc: must be a file path or a list of them, got {dbc!r}")
    paths = tuple(_coerce("can.dbc", d, Path, base) for d in dbc)
    section = _build_section(CanConfig, data, "can", base)
    for path in paths + (section.output_dbc,):
        key = "can.dbc" if path in paths else "can.output_dbc"
        _check_regular_file(key, path)
    return dataclasses.replace(section, dbc=paths)


def _not_a_regular_file(path: Path) -> str | None:
    """Why `path` cannot be read as a file (None if it is a regular file): never an OSError,
    and never a FIFO or device that would block the read."""
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        return "no such file"
    except ValueError:   # a NUL byte in the path
        return _UNUSABLE_PATH
    except OSError as exc:
        return f"cannot read: {exc.strerror or exc}"
    if stat.S_ISDIR(mode):
        return "is a directory"
    return None if stat.S_ISREG(mode) else "not a regular file"


_UNUSABLE_PATH = "not a usable file path"
_CONFIG_FILE_WORDING = {"no such file": "no such config file", "is a directory": "is a directory, not a config file",
                        "cannot read:": "cannot read config:"}


def _check_regular_file(key: str, path: Path) -> None:
    problem = _not_a_regular_file(path)
    if problem is not None:
        raise ConfigError(f"{key}: {_path_text(path, problem)}: {problem}")


def _path_text(path: Path, problem: str) -> str:
    """The path as a message shows it: shortened, and quoted when it cannot be a file name (a
    NUL byte would otherwise end up raw in the message)."""
    return repr(_short(path)) if problem == _UNUSABLE_PATH else _short(path)


def _short(path: Path) -> str:
    text = str(path)
    return text if len(text) <= 120 else text[:60] + "…" + text[-40:]


def _build_signals(data: Any) -> dict[str, SignalSource]:
    if not isinstance(data, dict):
        raise ConfigError(f"signals: must be a mapping of input name to message/signal, got {type(data).__name__}")
    known = REQUIRED_INPUTS + OPTIONAL_INPUTS
    signals: dict[str, SignalSource] = {}
    for name, spec in data.items():
        key = f"signals.{name}"
        if name not in known:
            raise ConfigError(f"{key}: unknown input (known: {', '.join(known)})")
        if spec is None:
            continue  # explicitly absent optional input
        if isinstance(spec, str):
            message, _, signal = spec.partition(".")
            if not message or not signal:
                raise ConfigError(f"{key}: write MESSAGE.Signal or a mapping with message and signal, got {spec!r}")
            spec = {"message": message, "signal": signal}
        if not isinstance(spec, dict):
            raise ConfigError(f"{key}: must be MESSAGE.Signal or a mapping, got {spec!r}")
        for required in ("message", "signal"):
            if required not in spec:
                raise ConfigError(f"{key}.{required}: missing")
        source = _build_section(SignalSource, spec, key, Path("."))
        if source.scale == 0.0:
            raise ConfigError(f"{key}.scale: must not be zero")
        signals[name] = source
    missing = [n for n in REQUIRED_INPUTS if n not in signals]
    if missing:
        raise ConfigError(f"signals: required input(s) not mapped: {', '.join(missing)}")
    return signals


class _BoundedLoader(yaml.SafeLoader):
    """SafeLoader that refuses documents with too many nodes (alias 'billion laughs' bombs)."""

    def construct_document(self, node):  # type: ignore[override]
        count = 0
        stack = [node]
        seen: set[int] = set()
        while stack:
            n = stack.pop()
            count += 1
            if count > MAX_YAML_NODES:
                raise ConfigError(f"YAML document too large or too deeply aliased (> {MAX_YAML_NODES} nodes)")
            if isinstance(n, yaml.SequenceNode):
                stack.extend(n.value)
            elif isinstance(n, yaml.MappingNode):
                for k, v in n.value:
                    stack.extend((k, v))
            seen.add(id(n))
        return super().construct_document(node)


def parse_config(data: Any, path: Path | None) -> Config:
    """Validate an already-parsed mapping (path only locates relative files)."""
    base = path.parent if path is not None else Path.cwd()
    if not isinstance(data, dict):
        raise ConfigError("top level: must be a mapping with can, vehicle, signals, ...")
    sections = {"can", "vehicle", "frontend", "estimator", "output", "daemon", "signals"}
    for key in data:
        if key not in sections:
            raise ConfigError(f"{key}: unknown section (known: {', '.join(sorted(sections))})")
    for key in ("can", "vehicle", "signals"):
        if key not in data:
            raise ConfigError(f"{key}: missing section")
    can = _build_can(data["can"], base)
    vehicle = _build_section(VehicleParams, data["vehicle"], "vehicle", base, _VEHICLE_RANGES)
    given = data["vehicle"] or {}   # (a mapping or nothing: `_build_section` refused the rest)
    if "drag_area_coefficient" not in given:
        doubt = vehicle.drag_area_doubt if "drag_area_doubt" in given else UNKNOWN_DRAG_AREA
        vehicle = dataclasses.replace(vehicle, drag_area_coefficient=UNKNOWN_DRAG_AREA, drag_area_doubt=doubt)
        logging.getLogger(__name__).warning(
            "vehicle.drag_area_coefficient not given: taken as %.2f ± %.2f kg/m (any car); at speed on a "
            "low-grip road the estimate is then less often VALID", UNKNOWN_DRAG_AREA, vehicle.drag_area_doubt)
    frontend = _build_section(FrontEndOptions, data.get("frontend"), "frontend", base)
    estimator = _build_section(EstimatorConfig, data.get("estimator"), "estimator", base)
    if estimator.kind not in ESTIMATOR_KINDS:
        raise ConfigError(f"estimator.kind: unknown estimator {estimator.kind!r} (known: {', '.join(ESTIMATOR_KINDS)})")
    output = _build_section(OutputConfig, data.get("output"), "output", base)
    if output.wheel_divider < 1:
        raise ConfigError("output.wheel_divider: must be ≥ 1")
    daemon = _build_section(DaemonConfig, data.get("daemon"), "daemon", base)
    if daemon.state_interval <= 0 or daemon.max_update_rate <= 0 or daemon.reconnect_max_backoff <= 0:
        raise ConfigError("daemon: state_interval, max_update_rate and reconnect_max_backoff must be > 0")
    signals = _build_signals(data["signals"])
    return Config(path, can, vehicle, frontend, estimator, output, daemon, types.MappingProxyType(signals))


def load_config(path: Path | str) -> Config:
    """Read and validate a YAML config file. Raises `ConfigError` naming the problem."""
    path = Path(path)
    problem = _not_a_regular_file(path)
    if problem is not None:
        name = _path_text(path, problem)
        for generic, specific in _CONFIG_FILE_WORDING.items():
            problem = problem.replace(generic, specific)
        raise ConfigError(f"{name}: {problem}")
    try:
        with open(path, "rb") as fh:
            raw = fh.read(MAX_CONFIG_BYTES + 1)
    except OSError as exc:
        raise ConfigError(f"{_short(path)}: cannot read config: {exc.strerror or exc}") from None
    if len(raw) > MAX_CONFIG_BYTES:
        raise ConfigError(f"{path}: config larger than {MAX_CONFIG_BYTES} bytes")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    try:
        data = yaml.load(text, Loader=_BoundedLoader)  # noqa: S506 - a SafeLoader subclass
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise ConfigError(f"{path}: invalid YAML{where}: {exc.problem}") from None
    except yaml.YAMLError as exc:   # e.g. ReaderError: its text spans lines; the contract is one line
        raise ConfigError(f"{path}: invalid YAML: {' '.join(str(exc).split())}") from None
    except RecursionError:
        raise ConfigError(f"{path}: YAML nested too deeply") from None
    try:
        return parse_config(data, path.resolve())
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
