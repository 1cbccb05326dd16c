"""CAN payloads ↔ values: input frames through the config's signal map, output frames with E2E.

The only module that imports cantools. Input values leave here in the canonical SI units of
docs/architecture.md (rad/s, m/s², rad/s, bar, m/s, N·m), whatever the vehicle's DBC uses.
"""
from __future__ import annotations

import logging
import math
import struct
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Mapping, NamedTuple, Sequence

import cantools
from cantools.database import Database

from .config import ConfigError, SignalSource
from .e2e import E2EChecker, protect
from .frames import Frame, frame_key
from .input_names import OPTIONAL_INPUTS, REQUIRED_INPUTS
from .samples import WHEELS, FrictionEstimate, PhysicalSample, Status

try:
    # Input decoding, output packing and E2E protection compiled (setup.py builds it when a C
    # compiler is there); the Python paths below and `e2e.protect` are the fallback and the reference.
    from . import _codeccore as compiled_codec
except ImportError:  # pragma: no cover - depends on the install
    compiled_codec = None

ESTIMATE_MESSAGE = "FRICTION_ESTIMATE"
WHEEL_MESSAGE = "FRICTION_WHEEL"
GRAVITY_MPS2 = 9.80665

# Quantity of each canonical input, and the units each quantity accepts (factor to SI).
_QUANTITY = {
    **{n: "wheel_speed" for n in REQUIRED_INPUTS if n.startswith("wheel_speed")},
    "accel_long": "acceleration",
    "accel_lat": "acceleration",
    "yaw_rate": "angular_rate",
    **{n: "pressure" for n in REQUIRED_INPUTS if n.startswith("brake_pressure")},
    "vehicle_speed_ref": "speed",
    **{n: "torque" for n in OPTIONAL_INPUTS if n.startswith("drive_torque")},
    "brake_pressure_master": "pressure",
    **{n: "flag" for n in OPTIONAL_INPUTS if n.startswith("abs_active")},
}
_DEG = math.pi / 180.0
_UNITS: dict[str, dict[str, float | None]] = {
    # None: "ground speed, divide by the wheel radius" (resolved per vehicle)
    "wheel_speed": {"rad/s": 1.0, "rad/sec": 1.0, "1/s": 1.0, "rpm": 2 * math.pi / 60, "1/min": 2 * math.pi / 60,
                    "U/min": 2 * math.pi / 60, "rev/min": 2 * math.pi / 60,
                    "deg/s": _DEG, "°/s": _DEG, "m/s": None, "m/sec": None, "km/h": None, "km/hr": None, "kph": None,
                    "kmh": None, "kmph": None, "mph": None},
    "acceleration": {"m/s^2": 1.0, "m/s²": 1.0, "m/s2": 1.0, "m/(s^2)": 1.0, "m/s/s": 1.0, "m/sec^2": 1.0,
                     "m/sec2": 1.0, "m/sec²": 1.0, "ms^-2": 1.0, "m*s^-2": 1.0, "g": GRAVITY_MPS2},
    "angular_rate": {"rad/s": 1.0, "rad/sec": 1.0, "deg/s": _DEG, "deg/sec": _DEG, "°/s": _DEG, "°/sec": _DEG},
    "pressure": {"bar": 1.0, "mbar": 1e-3, "hpa": 1e-3, "kpa": 0.01, "mpa": 10.0, "pa": 1e-5, "psi": 0.0689475729},
    "speed": {"m/s": 1.0, "m/sec": 1.0, "km/h": 1 / 3.6, "km/hr": 1 / 3.6, "kph": 1 / 3.6, "kmh": 1 / 3.6,
              "kmph": 1 / 3.6, "mph": 0.44704},
    "torque": {"n.m": 1.0, "nm": 1.0, "n*m": 1.0, "n·m": 1.0, "knm": 1000.0},
    "flag": {"1": 1.0, "-": 1.0, "bool": 1.0, "on/off": 1.0},
}
_GROUND_SPEED = {"m/s": 1.0, "m/sec": 1.0, "km/h": 1 / 3.6, "km/hr": 1 / 3.6, "kph": 1 / 3.6, "kmh": 1 / 3.6,
                 "kmph": 1 / 3.6, "mph": 0.44704}
CANONICAL_UNIT = {"wheel_speed": "rad/s", "acceleration": "m/s^2", "angular_rate": "rad/s",
                  "pressure": "bar", "speed": "m/s", "torque": "N.m", "flag": "1"}


class DecodeFailure(Exception):
    """An input frame that cannot be turned into values; `reason` is a short counter key."""

    def __init__(self, reason: str, detail: str = "") -> None:
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason


def _not_an_overwrite(record: logging.LogRecord) -> bool:
    """cantools' warning that a message replaced another of the same ID in its ID table: the codec
    finds such a pair itself where it matters (both mapped: a `ConfigError` naming them) and keys
    its inputs by ID and name, so it is no news to a user (and no second line to a config error)."""
    return not str(record.msg).startswith("Overwriting message")


def load_databases(paths: Sequence[Path | str], strict: bool = True) -> Database:
    """Load one or several DBC files into one database; `ConfigError` names the bad file."""
    db = Database(strict=strict)
    for path in paths:
        path = Path(path)
        try:
            with _filtered(logging.getLogger("cantools.database.can.database"), _not_an_overwrite):
                db.add_dbc_file(str(path))
        except FileNotFoundError:
            raise ConfigError(f"{path}: no such DBC file") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise ConfigError(f"{path}: cannot read DBC: {exc}") from None
        except Exception as exc:  # cantools raises parser, value and key errors alike
            text = " ".join(str(exc).split())[:200] or type(exc).__name__
            hint = " (try can.dbc_strict: false)" if strict else ""
            raise ConfigError(f"{path}: DBC does not parse: {text}{hint}") from None
    if not db.messages:
        raise ConfigError(f"{', '.join(map(str, paths))}: DBC defines no messages")
    return db


@contextmanager
def _filtered(logger: logging.Logger, keep: Callable[[logging.LogRecord], bool]) -> Iterator[None]:
    logger.addFilter(keep)
    try:
        yield
    finally:
        logger.removeFilter(keep)


@dataclass(frozen=True, slots=True)
class ResolvedSignal:
    """One canonical input bound to a DBC signal, with its conversion to SI."""

    name: str                    # canonical input name
    message: str
    signal: str
    dbc_unit: str
    unit: str                    # the unit assumed for the DBC's physical value
    factor: float                # SI = (physical * scale + offset) * factor
    scale: float
    offset: float
    multiplexer_ids: tuple[int, ...] | None
    minimum: float | None
    maximum: float | None
    note: str = ""

    def to_si(self, physical: float) -> float:
        return (physical * self.scale + self.offset) * self.factor

    def from_si(self, value: float) -> float:
        return (value / self.factor - self.offset) / self.scale


class InputMessage(NamedTuple):
    name: str
    frame_id: int
    period_s: float | None
    signals: tuple[str, ...]     # canonical names carried
    length: int
    is_multiplexed: bool
    is_extended: bool = False    # a 29-bit ID


class DecodedInput(NamedTuple):
    time_s: float
    message: str
    values: dict[str, float]
    is_trigger: bool


_new_tuple = tuple.__new__


def _resolve_unit(name: str, source: SignalSource, dbc_unit: str, wheel_radius: float,
                  list_units: bool = True) -> tuple[str, float, str]:
    """(the unit, its factor to SI, a note) of a mapped input; `list_units`: a refusal names the
    units known for its quantity (False where an earlier refusal of the same quantity did)."""
    quantity = _QUANTITY[name]
    table = _UNITS[quantity]
    declared = source.unit if source.unit is not None else dbc_unit
    note = ""
    key = (declared or "").strip().lower().replace(" ", "")
    lookup = {k.lower(): v for k, v in table.items()}
    if not key:
        key = CANONICAL_UNIT[quantity].lower()
        note = f"no unit in DBC; assumed {CANONICAL_UNIT[quantity]}"
    if key not in lookup:
        where = "signals." + name + ".unit" if source.unit is not None else f"DBC unit of {source.message}.{source.signal}"
        known = ", ".join(table) if list_units else "those named above"
        raise ConfigError(
            f"signals.{name}: {where} {declared!r} is not a {quantity.replace('_', ' ')} unit "
            f"(use one of {known}; set signals.{name}.unit to override)"
        )
    factor = lookup[key]
    if factor is None:  # ground speed of the wheel → angular speed
        factor = _GROUND_SPEED[key] / wheel_radius
    return declared or CANONICAL_UNIT[quantity], factor, note


def resolve_signals(db: Database, signals: Mapping[str, SignalSource], wheel_radius: float) -> list[ResolvedSignal]:
    """Bind every mapped input to its DBC signal; one `ConfigError` line names every missing piece."""
    resolved = []
    problems: list[str] = []
    units_listed: set[str] = set()
    for name, source in signals.items():
        try:
            message = db.get_message_by_name(source.message)
        except KeyError:
            problems.append(f"signals.{name}: message {source.message!r} is not in the DBC")
            continue
        try:
            signal = message.get_signal_by_name(source.signal)
        except KeyError:
            problems.append(f"signals.{name}: signal {source.signal!r} is not in message {source.message!r} of the DBC")
            continue
        dbc_unit = signal.unit or ""
        try:
            unit, factor, note = _resolve_unit(name, source, dbc_unit, wheel_radius,
                                               list_units=_QUANTITY[name] not in units_listed)
        except ConfigError as exc:
            problems.append(str(exc))
            units_listed.add(_QUANTITY[name])   # (four wheels, one list: the line stays short)
            continue
        mux = tuple(signal.multiplexer_ids) if signal.multiplexer_ids else None
        resolved.append(
            ResolvedSignal(name, message.name, signal.name, dbc_unit, unit, factor, source.scale, source.offset,
                           mux, signal.minimum, signal.maximum, note)
        )
    if problems:
        more = f" ({len(problems)} problems)" if len(problems) > 1 else ""
        raise ConfigError("; ".join(problems) + more)
    return resolved


def _bit_field(signal: Any, length: int) -> tuple[bool, int, int] | None:
    """(little-endian, shift, mask) of a signal in the payload read as one integer; None if unusable.

    Little-endian (Intel) signals are read from `int.from_bytes(data, "little")`, big-endian
    (Motorola) ones from `int.from_bytes(data, "big")`, exactly the bit positions cantools'
    bitstruct formats use.
    """
    n = signal.length
    if n <= 0:
        return None
    if signal.byte_order == "little_endian":
        shift = signal.start
    else:
        shift = 8 * length - (8 * (signal.start // 8) + (7 - signal.start % 8)) - n
    if shift < 0 or shift + n > 8 * length:
        return None
    return signal.byte_order == "little_endian", shift, (1 << n) - 1


def _simple_layout(message: Any) -> bool:
    """True when a message's signals can be read with shifts and masks, bit for bit as cantools."""
    if message.is_container or message.is_multiplexed() or not message.signals:
        return False
    used = [0, 0]   # bits taken, per byte order (cantools packs each order in its own format)
    for sig in message.signals:
        if sig.conversion.is_float or getattr(sig, "is_float", False):
            return False
        field = _bit_field(sig, message.length)
        if field is None:
            return False
        little, shift, mask = field
        bits = mask << shift
        if used[little] & bits:
            return False  # overlapping signals: leave them to cantools
        used[little] |= bits
    return True


def _scaler(conversion: Any) -> tuple[bool, Any, Any]:
    """(identity, scale, offset) reproducing `conversion.raw_to_scaled(raw, decode_choices=False)`."""
    inner = getattr(conversion, "_conversion", None)  # NamedSignalConversion delegates
    if inner is not None:
        conversion = inner
    if type(conversion).__name__ == "IdentityConversion":
        return True, 1, 0
    return False, conversion.scale, conversion.offset


class _MessagePlan:
    """Everything needed to decode one input message quickly."""

    __slots__ = ("message", "name", "frame_id", "is_extended", "key", "length", "signals", "is_trigger", "check_range",
                 "to_si", "fields",
                 "compiled")

    def __init__(self, message: Any, signals: list[ResolvedSignal], is_trigger: bool) -> None:
        self.message = message
        self.name = message.name
        self.frame_id = message.frame_id
        self.is_extended = bool(message.is_extended_frame)
        self.key = frame_key(self.frame_id, self.is_extended)
        self.length = message.length
        self.signals = signals
        self.is_trigger = is_trigger
        # DBC ranges that say something (min < max) mark invalid codes (e.g. 0xFFFF); the bounds
        # carry a relative tolerance of 1e-9 for values scaled to a limit.
        self.check_range = [
            (s, s.minimum - 1e-9 * abs(s.minimum) - 1e-9, s.maximum + 1e-9 * abs(s.maximum) + 1e-9)
            for s in signals
            if s.minimum is not None and s.maximum is not None and s.minimum < s.maximum
        ]
        # (DBC signal, canonical name, scale, offset, factor) of each mapped signal: `ResolvedSignal.to_si`.
        self.to_si = tuple((s.signal, s.name, s.scale, s.offset, s.factor) for s in signals)
        self.fields: tuple | None = None
        self.compiled: tuple | None = None

    def compile(self, counter: Any | None) -> None:
        """Fast path: the signals this plan reads (mapped ones and the alive counter), as
        shift/mask/sign/scale of the payload integer; `fields` None → decode with cantools."""
        message = self.message
        signals = self.signals
        self.fields = None
        if _simple_layout(message):
            wanted = {s.signal for s in signals} | ({counter.name} if counter is not None else set())
            fields = []
            for sig in message.signals:
                if sig.name not in wanted:
                    continue
                little, shift, mask = _bit_field(sig, message.length)  # type: ignore[misc]
                identity, scale, offset = _scaler(sig.conversion)
                sign = (1 << (sig.length - 1)) if sig.is_signed else 0
                fields.append((sig.name, little, shift, mask, sign, identity, scale, offset))
            self.fields = tuple(fields)
        self.compiled = self._compiled_spec(counter)

    def _compiled_spec(self, counter: Any | None) -> tuple | None:
        """`_codeccore.unpack_si`'s tables (all but the payload): for a classical payload read
        with shifts and masks whose values a double holds exactly (fields of ≤ 52 bits, integer
        scalings below 2**53), so that it computes what `unpack` and `to_si` compute; else None."""
        if self.fields is None or self.length > 8:
            return None
        index = {}
        fields = []
        for k, (name, little, shift, mask, sign, identity, scale, offset) in enumerate(self.fields):
            if mask.bit_length() > 52 or not all(isinstance(x, (int, float)) for x in (scale, offset)):
                return None
            if not identity and isinstance(scale, int) and isinstance(offset, int) and \
                    mask * abs(scale) + abs(offset) >= 1 << 53:
                return None
            index[name] = k
            fields.append(struct.pack("<2qQ2q2d", little, shift, mask, sign, identity, scale, offset))
        checks = b"".join(struct.pack("<q2d", index[s.signal], low, high) for s, low, high in self.check_range)
        si = b"".join(struct.pack("<q3d", index[signal], scale, offset, factor)
                      for signal, _, scale, offset, factor in self.to_si)
        names = tuple(name for _, name, _, _, _ in self.to_si)
        counter_index = index.get(counter.name, -1) if counter is not None else -1
        return b"".join(fields), checks, si, names, counter_index

    def unpack(self, data: bytes) -> dict[str, Any]:
        """The wanted signals' scaled values; identical to cantools' `decode(..., decode_choices=False)`."""
        little_int = int.from_bytes(data, "little")
        big_int = int.from_bytes(data, "big")
        out = {}
        for name, little, shift, mask, sign, identity, scale, offset in self.fields:  # type: ignore[union-attr]
            raw = ((little_int if little else big_int) >> shift) & mask
            if sign and raw & sign:
                raw -= sign << 1
            out[name] = raw if identity else raw * scale + offset
        return out


class InputCodec:
    """Decodes the configured input messages into canonical SI values (and encodes, for the simulator)."""

    def __init__(self, db: Database, signals: Mapping[str, SignalSource], wheel_radius: float) -> None:
        self.db = db
        self.resolved = resolve_signals(db, signals, wheel_radius)
        by_message: dict[str, list[ResolvedSignal]] = {}
        for r in self.resolved:
            by_message.setdefault(r.message, []).append(r)
        # The message of wheel_speed_fl triggers each update; the other wheels' speeds may come from
        # other messages (a car that sends front and rear apart), joined at its instants
        # (`wheel_speed_join`).
        wheel_messages: dict[str, list[str]] = {}
        for r in self.resolved:
            if r.name.startswith("wheel_speed"):
                wheel_messages.setdefault(r.message, []).append(r.name)
        if not wheel_messages:
            raise ConfigError("signals: no wheel speed mapped (the message of wheel_speed_fl triggers each update)")
        self.trigger_message = next((r.message for r in self.resolved if r.name == "wheel_speed_fl"),
                                    next(iter(wheel_messages)))
        self.wheel_partners: dict[str, tuple[str, ...]] = {
            m: tuple(names) for m, names in wheel_messages.items() if m != self.trigger_message}
        self._plans: dict[int, _MessagePlan] = {}
        for name, sigs in by_message.items():
            plan = _MessagePlan(db.get_message_by_name(name), sigs, name == self.trigger_message)
            if plan.key in self._plans:
                raise ConfigError(f"signals: two mapped messages share frame ID 0x{plan.frame_id:X}: "
                                  f"{self._plans[plan.key].name!r} and {name!r}")
            if name in self.wheel_partners and plan.message.is_multiplexed():
                raise ConfigError(
                    f"signals: wheel speeds from message {name!r}, which is multiplexed: wheel speeds that come "
                    f"apart from {self.trigger_message!r} (the message of wheel_speed_fl) must be whole in every frame")
            self._plans[plan.key] = plan
        # The inputs' IDs as numbers (a first cheap test of a frame), and those sent as 29-bit IDs.
        self.input_ids: frozenset[int] = frozenset(p.frame_id for p in self._plans.values())
        self.extended_input_ids: frozenset[int] = frozenset(p.frame_id for p in self._plans.values() if p.is_extended)
        # Inputs sent as CAN FD frames (the DBC says so, or they carry more than 8 bytes): a
        # SocketCAN socket receives them only when opened for FD (`busio.open_bus`).
        self.fd = any(bool(getattr(p.message, "is_fd", False)) or p.length > 8 for p in self._plans.values())
        trigger_plan = next(p for p in self._plans.values() if p.is_trigger)
        self.trigger_id, self.trigger_extended = trigger_plan.frame_id, trigger_plan.is_extended
        self.counter_jumps = 0
        self._counter_signals = {   # (by the plans' keys, as the counters below)
            key: next((s for s in p.message.signals if _is_counter_name(s.name) and not s.multiplexer_ids), None)
            for key, p in self._plans.items()
        }
        for fid, plan in self._plans.items():
            plan.compile(self._counter_signals.get(fid))
        self._last_counter: dict[int, int] = {}
        self._encode_counters: dict[int, int] = {}
        self.core = compiled_codec

    def counter_signal(self, message: str) -> str | None:
        """Name of the alive counter checked in an input message (None: the message has none)."""
        plan = next(p for p in self._plans.values() if p.name == message)
        signal = self._counter_signals.get(plan.key)
        return signal.name if signal is not None else None

    def pages(self, message: str) -> int:
        """Number of multiplexer pages a message cycles through (1 if not multiplexed)."""
        plan = next(p for p in self._plans.values() if p.name == message)
        ids = {i for s in plan.message.signals for i in (s.multiplexer_ids or ())}
        return max(1, len(ids))

    def input_messages(self) -> list[InputMessage]:
        out = []
        for plan in self._plans.values():
            cycle = plan.message.cycle_time
            out.append(
                InputMessage(plan.name, plan.frame_id, cycle / 1000.0 if cycle else None,
                             tuple(s.name for s in plan.signals), plan.length, plan.message.is_multiplexed(),
                             plan.is_extended)
            )
        return out

    def decode(self, frame: Frame) -> DecodedInput | None:
        """Canonical values of an input frame; None for frames that are not inputs.

        Raises `DecodeFailure` for input frames that cannot be trusted (wrong length, a mapped
        signal outside its DBC range or not finite).
        """
        plan = self._plans.get(frame_key(frame.can_id, frame.is_extended))
        if plan is None:
            return None
        data = frame.data
        if len(data) != plan.length:
            raise DecodeFailure("wrong length", f"{plan.name} has {len(data)} bytes, DBC says {plan.length}")
        if plan.compiled is not None and self.core is not None:
            decoded = self.core.unpack_si(*plan.compiled, data)
            if decoded is not None:
                values, counter = decoded
                if counter is not None:
                    self._count(plan.key, counter)
                # (tuple.__new__: the NamedTuple without its Python-level __new__, a frame per input)
                return _new_tuple(DecodedInput, (frame.time_s, plan.name, values, plan.is_trigger))
            # Refused (a range or a value): the Python path below says why.
        if plan.fields is not None:
            raw = plan.unpack(data)
        else:
            try:
                raw = plan.message.decode(data, decode_choices=False, scaling=True)
            except Exception as exc:  # bad multiplexer value, truncated, ...
                raise DecodeFailure("undecodable", f"{plan.name}: {exc}") from None
        # The counter says whether frames were lost on the bus, even if we refuse this one's values.
        self._check_counter(plan.key, raw)
        for s, low, high in plan.check_range:
            value = raw.get(s.signal)
            if value is not None and not low <= value <= high:
                raise DecodeFailure("out of range", f"{plan.name}.{s.signal} = {value}")
        values = {}
        isfinite = math.isfinite
        for signal, name, scale, offset, factor in plan.to_si:
            physical = raw.get(signal)
            if physical is None:
                continue  # another multiplexer page
            v = (float(physical) * scale + offset) * factor   # ResolvedSignal.to_si, without the call
            if not isfinite(v):
                raise DecodeFailure("not finite", f"{plan.name}.{signal}")
            values[name] = v
        return DecodedInput(frame.time_s, plan.name, values, plan.is_trigger)

    def _check_counter(self, key: int, raw: Mapping[str, Any]) -> None:
        signal = self._counter_signals.get(key)
        if signal is None:
            return
        value = raw.get(signal.name)
        if value is not None:
            self._count(key, value)

    def _count(self, key: int, value: Any) -> None:
        """Counts a jump of a message's alive counter (`key`: `frame_key` of the message; value:
        the counter signal's value)."""
        signal = self._counter_signals[key]
        counter = int(value)
        last = self._last_counter.get(key)
        self._last_counter[key] = counter
        modulo = 1 << signal.length
        if last is not None and (counter - last) % modulo not in (1,):
            self.counter_jumps += 1

    def encode_input(self, message: str, values: Mapping[str, float]) -> list[bytes]:
        """Payloads carrying the given canonical values (several for a multiplexed message)."""
        plan = next(p for p in self._plans.values() if p.name == message)
        msg = plan.message
        pages: dict[int | None, dict[str, float]] = {}
        for s in plan.signals:
            if s.name not in values:
                continue
            keys = s.multiplexer_ids or (None,)
            page = pages.setdefault(keys[0], {})
            # Several inputs on one signal (a master-cylinder pressure split by axle factors):
            # the first mapped one (config order, FL first) sets it.
            page.setdefault(s.signal, s.from_si(values[s.name]))
        payloads = []
        counter_signal = self._counter_signals.get(plan.key)
        counter = self._encode_counters.get(plan.key, 0)
        self._encode_counters[plan.key] = counter + 1
        if counter_signal is not None:
            counter %= 1 << counter_signal.length
        for mux_id, page in pages.items():
            full = {}
            for sig in msg.signals:
                if sig.is_multiplexer:
                    full[sig.name] = mux_id if mux_id is not None else 0
                elif sig.multiplexer_ids and mux_id not in sig.multiplexer_ids:
                    continue
                elif counter_signal is not None and sig.name == counter_signal.name:
                    full[sig.name] = counter
                else:
                    full[sig.name] = page.get(sig.name, _idle_value(sig))
            for sig in msg.signals:
                if sig.name in full and sig.name in page:
                    full[sig.name] = _clip(sig, full[sig.name])
            payloads.append(bytes(msg.encode(full, scaling=True, strict=False, padding=False)))
        return payloads


_COUNTER_NAMES = ("counter", "alive_counter", "alivecounter", "msgcounter", "rolling_counter", "rollingcounter", "bz")
_COUNTER_SUFFIXES = ("_counter", "alivecounter", "rollingcounter", "_cnt_alive", "_bz")


def _is_counter_name(name: str) -> bool:
    """Alive/rolling counters by their usual names (Counter, ESP_21_Counter, AliveCounter, ..._BZ)."""
    low = name.lower()
    return low in _COUNTER_NAMES or low.endswith(_COUNTER_SUFFIXES)


def _idle_value(signal: Any) -> float:
    """A value for DBC signals we do not map (counters, checksums, other ECUs' data)."""
    low = signal.minimum if signal.minimum is not None else None
    if low is not None and low > 0:
        return low
    return 0.0 if signal.offset <= 0 <= (signal.maximum if signal.maximum is not None else math.inf) else signal.offset


def _limits(signal: Any) -> tuple[float, float]:
    """The physical range a signal's bits (and its DBC range) can carry."""
    bits = signal.length
    if signal.is_signed:
        raw_low, raw_high = -(1 << (bits - 1)), (1 << (bits - 1)) - 1
    else:
        raw_low, raw_high = 0, (1 << bits) - 1
    lo = raw_low * signal.scale + signal.offset
    hi = raw_high * signal.scale + signal.offset
    if signal.scale < 0:
        lo, hi = hi, lo
    if signal.minimum is not None and signal.maximum is not None and signal.minimum < signal.maximum:
        lo, hi = max(lo, signal.minimum), min(hi, signal.maximum)
    return lo, hi


def _clip(signal: Any, value: float) -> float:
    """Keep a value within what the signal's bits (and DBC range) can carry; not finite → low end."""
    lo, hi = _limits(signal)
    return _clamp(value, lo, hi) if math.isfinite(value) else lo


# -------------------------------------------------------------------------------- outputs
def _clamp(value: Any, lo: float, hi: float) -> Any:
    """A value within [lo, hi]; NaN → lo (never NaN on the bus)."""
    return min(max(value, lo), hi) if value == value else lo


class _Packer:
    """`message.encode(clipped values, scaling=True, strict=False, padding=False)` with shifts and masks.

    Each value is first clipped to what its signal can carry (`limits`, NaN → the low limit).
    Mirrors cantools' walk of the codec tree (multiplexed pages included), flattened per page
    into one list of fields; a message it cannot reproduce bit for bit (float or overlapping
    signals, containers), or a raw value outside its field, goes to cantools itself.
    """

    def __init__(self, message: Any, limits: Mapping[str, tuple[float, float]]) -> None:
        self.message = message
        self.length = message.length
        self.limits = limits
        self.root = self._compile(message._codecs) if not message.is_container and _packable(message) else None
        # Flattened fields by the top-level multiplexer values; only when no page nests another
        # multiplexer (then those values alone choose the fields).
        self._flat: dict[tuple, tuple] | None = None
        if self.root is not None and not any(sub[1] for _, _, _, pages in self.root[1] for sub in pages.values()):
            self._flat = {}
        # `_codeccore`'s field tables, by id() of the field tuples they were built from (only
        # tuples this packer keeps for its lifetime: the root's, and the flattened pages').
        self._specs: dict[int, tuple[bytes, tuple[str, ...]]] = {}
        if self.root is not None and not self.root[1]:
            self._register(self.root[0])

    def _register(self, fields: tuple) -> None:
        """Build `_codeccore.encode_frame`'s field table for a page: a classical payload whose fields all
        use linear or identity integer conversions of ≤ 52 bits (raw values a double holds
        exactly); other pages keep to the Python path."""
        if self.length > 8:
            return
        specs, names = [], []
        for name, lo, hi, scale, offset, to_raw, little, shift, mask, low, high in fields:
            # The conversion behind a `numeric_scaled_to_raw` (a signal with value names
            # delegates to its numeric conversion).
            conversion = getattr(to_raw, "__self__", None)
            kind = type(conversion).__name__
            if kind == "LinearIntegerConversion":
                # Its exact-quotient branch gives what round((value - offset) / scale) gives
                # while raw values stay below 2**53, which the width check below ensures.
                scale, offset, to_raw = conversion.scale, conversion.offset, None
            elif kind == "IdentityConversion" and not conversion.is_float:
                scale, offset, to_raw = None, 0, None
            if to_raw is not None or mask.bit_length() > 52:
                return
            specs.append(struct.pack("<4d3qQ2q", lo, hi, 1.0 if scale is None else scale, offset,
                                     scale is None, little, shift, mask, low, high))
            names.append(name)
        self._specs[id(fields)] = (b"".join(specs), tuple(names))

    def _compile(self, node: dict) -> tuple:
        fields = []
        for sig in node["signals"]:
            little, shift, mask = _bit_field(sig, self.length)  # type: ignore[misc]
            if sig.is_signed:
                low, high = -(1 << (sig.length - 1)), (1 << (sig.length - 1)) - 1
            else:
                low, high = 0, mask
            lo, hi = self.limits[sig.name]
            scale, offset, to_raw = _raw_of(sig.conversion)
            fields.append((sig.name, lo, hi, scale, offset, to_raw, little, shift, mask, low, high))
        muxes = tuple(
            (name, *self.limits[name], {mux: self._compile(sub) for mux, sub in pages.items()})
            for name, pages in node["multiplexers"].items()
        )
        return tuple(fields), muxes

    def encode(self, values: Mapping[str, Any]) -> bytes:
        fields = None
        if self.root is not None:
            fields = self._fields(values)
        if fields is not None:
            big = little_word = 0  # the payload read as a big-endian and as a little-endian integer
            for name, lo, hi, scale, offset, to_raw, little, shift, mask, low, high in fields:
                value = values[name]
                if value != value:
                    value = lo  # NaN
                else:  # min(max(value, lo), hi), without the calls
                    if lo > value:
                        value = lo
                    if hi < value:
                        value = hi
                if not isinstance(value, (int, float)):
                    break  # choice names and the like: cantools' own path
                if to_raw is not None:
                    raw = to_raw(value)
                elif scale is None:
                    raw = round(value)  # IdentityConversion.numeric_scaled_to_raw
                else:
                    raw = round((value - offset) / scale)  # LinearConversion.numeric_scaled_to_raw
                if not low <= raw <= high:
                    break
                if little:
                    little_word |= (raw & mask) << shift
                else:
                    big |= (raw & mask) << shift
            else:
                n = self.length
                if not big:
                    return little_word.to_bytes(n, "little")
                little_bytes = little_word.to_bytes(n, "little")
                return (int.from_bytes(little_bytes, "big") | big).to_bytes(n, "big")
        clipped = {}
        for name, value in values.items():
            clipped[name] = _clamp(value, *self.limits[name])
        return bytes(self.message.encode(clipped, scaling=True, strict=False, padding=False))

    def _fields(self, values: Mapping[str, Any]) -> tuple | None:
        """The fields of the pages the (clipped) multiplexer values select; None: no such page."""
        fields, muxes = self.root  # type: ignore[misc]
        if not muxes:
            return fields
        if self._flat is None:
            return self._walk(self.root, values)  # type: ignore[arg-type]
        key = tuple([_clamp(values[name], lo, hi) for name, lo, hi, _ in muxes])
        fields = self._flat.get(key)
        if fields is None:
            fields = self._walk(self.root, values)  # type: ignore[arg-type]
            if fields is not None:
                self._flat[key] = fields
                self._register(fields)
        return fields

    def spec_for(self, values: Mapping[str, Any]) -> tuple[bytes, tuple[str, ...]] | None:
        """`_codeccore`'s field table for the page these values select; None: the Python path."""
        fields = self._fields(values) if self.root is not None else None
        return self._specs.get(id(fields)) if fields is not None else None

    def _walk(self, node: tuple, values: Mapping[str, Any]) -> tuple | None:
        fields, muxes = node
        for name, lo, hi, pages in muxes:
            value = _clamp(values[name], lo, hi)
            if not isinstance(value, (int, float)):
                return None
            sub = pages.get(value)
            if sub is None:
                return None
            sub_fields = self._walk(sub, values)
            if sub_fields is None:
                return None
            fields = fields + sub_fields
        return fields


def _raw_of(conversion: Any) -> tuple[float | None, float, Any]:
    """(scale, offset, None) for the integer conversions `_Packer` computes inline (scale None:
    identity); (None, 0, conversion.numeric_scaled_to_raw) for any other, called as is."""
    kind = type(conversion).__name__
    if kind == "IdentityConversion" and not conversion.is_float:
        return None, 0, None
    if kind == "LinearConversion" and not conversion.is_float:
        return conversion.scale, conversion.offset, None
    return None, 0, conversion.numeric_scaled_to_raw


def _packable(message: Any) -> bool:
    """Every signal of the message (on any page) an integer field inside the payload."""
    for sig in message.signals:
        if sig.conversion.is_float or getattr(sig, "is_float", False) or _bit_field(sig, message.length) is None:
            return False

    def walk(node: dict) -> bool:
        used = [0, 0]
        for sig in node["signals"]:
            little, shift, mask = _bit_field(sig, message.length)  # type: ignore[misc]
            if used[little] & (mask << shift):
                return False
            used[little] |= mask << shift
        return all(walk(sub) for pages in node["multiplexers"].values() for sub in pages.values())

    return message._codecs is not None and walk(message._codecs)


class OutputCodec:
    """FRICTION_ESTIMATE / FRICTION_WHEEL encoding with the E2E counter and CRC; decoding for tools."""

    def __init__(self, db: Database) -> None:
        try:
            self.estimate_message = db.get_message_by_name(ESTIMATE_MESSAGE)
            self.wheel_message = db.get_message_by_name(WHEEL_MESSAGE)
        except KeyError as exc:
            raise ConfigError(f"can.output_dbc: lacks message {exc.args[0]!r}") from None
        for message, names in (
            (self.estimate_message, ("Crc", "Counter", "EstimatorStatus", "MuMax", "SlipAtMuMax", "Theta", "Confidence")),
            (self.wheel_message, ("Crc", "Counter", "WheelIndex", "Slip", "MuUsed", "MuMaxWheel", "NormalForce")),
        ):
            present = {s.name for s in message.signals}
            missing = [n for n in names if n not in present]
            if missing:
                raise ConfigError(f"can.output_dbc: {message.name} lacks signal(s) {', '.join(missing)}")
            crc, counter = message.get_signal_by_name("Crc"), message.get_signal_by_name("Counter")
            if not (crc.start == 0 and crc.length == 8 and crc.byte_order == "little_endian"
                    and counter.length == 4 and counter.byte_order == "little_endian"
                    and counter.start % 8 <= 4 and counter.start < 8 * message.length):
                # e2e.protect writes the CRC into byte 0 and the counter as a nibble of one byte.
                raise ConfigError(f"can.output_dbc: {message.name} needs Crc as 0|8@1+ and Counter as a "
                                  f"4-bit little-endian field within one byte (can-contract.md)")
        self.estimate_id: int = self.estimate_message.frame_id
        self.wheel_id: int = self.wheel_message.frame_id
        self._signals = {m.frame_id: {s.name: s for s in m.signals} for m in (self.estimate_message, self.wheel_message)}
        # Signals a vehicle's output DBC adds beyond the contract's (spare bits, another ECU's
        # fields) are sent at their idle value rather than refused or left to fail at send time.
        contract = {"Crc", "Counter", "EstimatorStatus", "MuMax", "SlipAtMuMax", "Theta", "Confidence",
                    "WheelIndex", "Slip", "MuUsed", "MuMaxWheel", "NormalForce"}
        self._extra_values = {
            fid: {name: _idle_value(sig) for name, sig in sigs.items() if name not in contract}
            for fid, sigs in self._signals.items()
        }
        self._counters = {self.estimate_id: 0, self.wheel_id: 0}
        self._counter_bit = {
            fid: sigs["Counter"].start for fid, sigs in self._signals.items()
        }
        self._packers = {
            fid: _Packer(m, {name: _limits(sig) for name, sig in self._signals[fid].items()})
            for fid, m in ((self.estimate_id, self.estimate_message), (self.wheel_id, self.wheel_message))
        }
        self.e2e = E2EChecker()
        self.core = compiled_codec
        # The compiled field tables of the pages sent every update, looked up once where the
        # values cannot change the page: the estimate's when it has no multiplexer, each wheel's
        # when WheelIndex alone chooses it. Any other page is looked up per frame (`_encode`).
        self._estimate_spec = self._fixed_spec(self.estimate_id, {})
        self._wheel_specs = tuple(self._fixed_spec(self.wheel_id, {"WheelIndex": i}) for i in range(len(WHEELS)))

    def _fixed_spec(self, frame_id: int, chosen: dict[str, int]) -> tuple | None:
        """The compiled field table of the page that the multiplexer values `chosen` select,
        when those are all the message's multiplexers; None: looked up per frame."""
        packer = self._packers[frame_id]
        if packer.root is None or any(name not in chosen for name, *_ in packer.root[1]):
            return None
        return packer.spec_for({**{name: 0 for name in self._signals[frame_id]}, **chosen})

    def _encode(self, frame_id: int, message: Any, values: dict[str, float], spec: tuple | None = None) -> bytes:
        """One frame's payload with its counter and CRC: compiled when its page has a field table
        (`spec`, or the packer's for these values), else the Python packer and `e2e.protect`."""
        extra = self._extra_values[frame_id]
        if extra:
            values.update(extra)
        counter = self._counters[frame_id]
        self._counters[frame_id] = (counter + 1) & 0x0F
        packer = self._packers[frame_id]
        if self.core is not None:
            if spec is None:
                spec = packer.spec_for(values)
            if spec is not None:
                payload = self.core.encode_frame(spec[0], spec[1], values, message.length, frame_id, counter,
                                                 self._counter_bit[frame_id])
                if payload is not None:
                    return payload
        return bytes(protect(frame_id, bytearray(packer.encode(values)), counter, self._counter_bit[frame_id]))

    def encode_estimate(self, estimate: FrictionEstimate) -> bytes:
        status = int(estimate.status)
        numbers = mu, slip, theta, confidence = (estimate.mu_max, estimate.slip_at_mu_max, estimate.theta,
                                                 estimate.confidence)
        isfinite = math.isfinite
        if not (isfinite(mu) and isfinite(slip) and isfinite(theta) and isfinite(confidence)):
            # Never put NaN/inf on the bus; say FAULT instead of a number nobody can trust.
            status = int(Status.FAULT)
            numbers = tuple(x if math.isfinite(x) else 0.0 for x in numbers)
        mu, slip, theta, confidence = numbers
        return self._encode(self.estimate_id, self.estimate_message, {
            "Crc": 0, "Counter": 0, "EstimatorStatus": status, "MuMax": mu, "SlipAtMuMax": slip,
            "Theta": theta, "Confidence": confidence,
        }, self._estimate_spec)

    def encode_wheels(self, estimate: FrictionEstimate, sample: PhysicalSample) -> list[bytes]:
        slips, mus_used, mus_max, loads = sample.slip, sample.mu_used, estimate.wheel_mu_max, sample.normal_force_n
        if self.core is not None and None not in self._wheel_specs:
            # The four frames in one compiled call (each as `_encode` would make it).
            counter = self._counters[self.wheel_id]
            payloads = self.core.encode_wheels(self._wheel_specs, self.wheel_message.length, self.wheel_id,
                                               counter, self._counter_bit[self.wheel_id], slips, mus_used, mus_max,
                                               loads, self._extra_values[self.wheel_id])
            if payloads is not None:
                self._counters[self.wheel_id] = (counter + len(payloads)) & 0x0F
                return payloads
        payloads = []
        for i, spec in enumerate(self._wheel_specs):
            payloads.append(self._encode(self.wheel_id, self.wheel_message, {
                "Crc": 0, "Counter": 0, "WheelIndex": i,
                "Slip": _finite(slips[i]), "MuUsed": _finite(mus_used[i]),
                "MuMaxWheel": _finite(mus_max[i]), "NormalForce": _finite(loads[i]),
            }, spec))
        return payloads

    def decode_output(self, frame: Frame) -> dict[str, Any] | None:
        """Signals of an output frame by name, plus 'message', 'time_s' and the E2E verdict 'e2e'."""
        if frame.can_id == self.estimate_id:
            message = self.estimate_message
        elif frame.can_id == self.wheel_id:
            message = self.wheel_message
        else:
            return None
        if len(frame.data) != message.length:
            self.e2e.crc_failures += 1
            return {"message": message.name, "time_s": frame.time_s, "e2e": "length"}
        verdict = self.e2e.check(frame.can_id, bytes(frame.data), self._counter_bit[frame.can_id])
        try:
            values = dict(message.decode(frame.data, decode_choices=True, scaling=True))
        except Exception:
            return {"message": message.name, "time_s": frame.time_s, "e2e": "undecodable"}
        for key, value in values.items():
            if not isinstance(value, (int, float)):
                values[key] = str(value)
        values.update(message=message.name, time_s=frame.time_s, e2e=verdict)
        return values


def _finite(x: float) -> float:
    return x if math.isfinite(x) else 0.0


def output_codec_for(paths: Iterable[Path | str]) -> OutputCodec:
    return OutputCodec(load_databases(list(paths), strict=True))


def validate_against_dbc(config: Any) -> tuple[InputCodec, OutputCodec]:
    """Build both codecs once: every mapped signal exists, units resolve, outputs are present."""
    input_codec = InputCodec(load_databases(config.can.dbc, strict=config.can.dbc_strict), config.signals,
                             config.vehicle.wheel_radius)
    output_codec = OutputCodec(load_databases([config.can.output_dbc], strict=True))
    standard_inputs = {m.frame_id for m in input_codec.input_messages() if not m.is_extended}
    overlap = standard_inputs & {output_codec.estimate_id, output_codec.wheel_id}   # (the outputs are 11-bit)
    if overlap:
        raise ConfigError(f"signals: input message ID 0x{min(overlap):X} collides with frictiond's output frames")
    return input_codec, output_codec
