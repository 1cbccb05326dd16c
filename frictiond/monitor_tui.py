"""The full-screen view of `frictiond monitor` (curses).

`render(...)` turns a `MonitorSnapshot` into lines of (text, style) segments for a given screen
size — plain data, testable without a terminal; `run(...)` is the curses loop that feeds the model
from a source, handles keys (q quit, p pause, r reset counters) and resizes, and draws.
"""
from __future__ import annotations

import curses
import locale
import time
from typing import Any, Sequence

from .monitor import InputRow, MonitorModel, MonitorSnapshot
from .samples import WHEELS

Segment = tuple[str, str]      # (text, style name)
Line = list[Segment]

STATUS_STYLE = {
    "VALID": "good",
    "CONVERGING": "warn",
    "NOT_EXCITED": "info",
    "INIT": "info",
    "INPUT_STALE": "stale",
    "FAULT": "bad",
}
SPARK_UNICODE = "▁▂▃▄▅▆▇█"
SPARK_ASCII = "_.-:=+*#"
KEYS_HELP = "q quit  p pause  r reset"
REDRAW_S = 0.1
POLL_S = 0.05

_FONT = {
    "0": ("###", "# #", "# #", "# #", "###"),
    "1": (" # ", "## ", " # ", " # ", "###"),
    "2": ("###", "  #", "###", "#  ", "###"),
    "3": ("###", "  #", "###", "  #", "###"),
    "4": ("# #", "# #", "###", "  #", "  #"),
    "5": ("###", "#  ", "###", "  #", "###"),
    "6": ("###", "#  ", "###", "# #", "###"),
    "7": ("###", "  #", "  #", "  #", "  #"),
    "8": ("###", "# #", "###", "# #", "###"),
    "9": ("###", "# #", "###", "  #", "###"),
    ".": (" ", " ", " ", " ", "#"),
    "-": ("   ", "   ", "###", "   ", "   "),
    "?": ("###", "  #", " ##", "   ", " # "),
}
BIG_ROWS = 5


def big_text(text: str, unicode: bool = True) -> list[str]:
    """`text` in a 5-row block font (digits, '.', '-')."""
    rows = [""] * BIG_ROWS
    for ch in text:
        glyph = _FONT.get(ch, _FONT["?"])
        for i in range(BIG_ROWS):
            rows[i] += glyph[i] + " "
    block = "█" if unicode else "#"
    return [r.rstrip().replace("#", block) for r in rows]


def sparkline(values: Sequence[float], width: int, lo: float, hi: float, unicode: bool = True) -> str:
    chars = SPARK_UNICODE if unicode else SPARK_ASCII
    if width <= 0 or not values:
        return ""
    values = list(values)[-width:]
    span = hi - lo if hi > lo else 1.0
    out = []
    for v in values:
        k = int(round((v - lo) / span * (len(chars) - 1)))
        out.append(chars[min(max(k, 0), len(chars) - 1)])
    return "".join(out)


def _fmt(value: float | None, spec: str, missing: str = "—") -> str:
    if value is None:
        return missing
    try:
        return format(value, spec)
    except (TypeError, ValueError):
        return str(value)


def _rate_row(row: InputRow, name_width: int, unicode: bool) -> Line:
    dash = "—" if unicode else "-"
    age = f"{row.age_s:7.3f} s" if row.age_s is not None else f"{dash:>9s}"
    rate = f"{row.rate_hz:7.1f} Hz" if row.rate_hz is not None else f"{dash:>10s}"
    expected = f"{1.0 / row.period_s:6.0f} Hz" if row.period_s else f"{dash:>9s}"
    name = ("→ " if unicode else "> ") + row.name if row.is_output else row.name
    style = "bad" if row.age_s is None and not row.is_output else ("warn" if row.stale else "normal")
    if row.age_s is None and row.is_output:
        style = "dim"
    text = f"{name[:name_width]:<{name_width}s} 0x{row.frame_id:03X} {age} {rate} {expected} {row.count:9d}"
    return [(text, style)]


def render(snap: MonitorSnapshot, width: int, height: int, paused: bool = False, unicode: bool = True,
           waiting_on: str = "") -> list[Line]:
    """The screen as lines of segments, at most `height` lines, each meant to be clipped at `width`."""
    if width <= 0 or height <= 0:
        return []
    lines: list[Line] = []
    dot = " · " if unicode else " | "
    # -- header
    head = "frictiond monitor" + dot + (snap.source or "?")
    if snap.now_s is not None:
        head += f"{dot}t {snap.now_s:.2f} s"
    head += f"{dot}{snap.frames_total} frames"
    flags = ("PAUSED  " if paused else "") + ("END OF LOG  " if snap.finished else "") + KEYS_HELP
    if len(head) + len(flags) + 2 <= width:
        lines.append([(head + " " * (width - len(head) - len(flags)), "header"), (flags, "header")])
    elif width - len(flags) >= 24:
        lines.append([(head[:width - len(flags) - 2] + "  ", "header"), (flags, "header")])
    else:
        lines.append([(("PAUSED " if paused else "") + head, "header")])

    est = snap.estimate
    if est is None:
        if snap.frames_total == 0 and snap.now_s is None:
            lines.append([(f"waiting for frames on {waiting_on or snap.source}", "warn")])
        else:
            lines.append([(f"no FRICTION_ESTIMATE yet ({snap.frames_total} frames seen)", "warn")])
    body = _body(snap, width, unicode)
    compact = _estimate_compact(snap, unicode) if est is not None else []
    big = _estimate_big(snap, width, unicode) if est is not None else []
    if est is not None:
        if big and len(lines) + len(big) + len(body) <= height:
            lines.extend(big)
        else:
            lines.extend(compact)
    lines.extend(body)
    return lines[:height]


def _estimate_compact(snap: MonitorSnapshot, unicode: bool) -> list[Line]:
    est = snap.estimate
    assert est is not None
    style = STATUS_STYLE.get(est.status, "bad")
    return [[
        (f"MuMax {est.mu_max:.3f} ", "bigvalue"), (f" {est.status} ", style + "_inv"),
        (f" confidence {est.confidence:.2f}  slip at peak {est.slip_at_mu_max:.3f}  theta {est.theta:.2f}"
         f"  e2e {est.e2e}", "normal"),
    ]]


def _estimate_big(snap: MonitorSnapshot, width: int, unicode: bool) -> list[Line]:
    est = snap.estimate
    assert est is not None
    style = STATUS_STYLE.get(est.status, "bad")
    digits = big_text(f"{est.mu_max:.3f}", unicode)
    left_w = max(len(r) for r in digits) + 3
    age = None if snap.now_s is None else max(0.0, snap.now_s - est.time_s)
    right: list[Line] = [
        [("MuMax ", "normal"), (f"{est.mu_max:.3f}", "bigvalue")],
        [("status ", "normal"), (f" {est.status} ", style + "_inv")],
        [(f"confidence {est.confidence:.2f}   slip at peak {est.slip_at_mu_max:.3f}", "normal")],
        [(f"theta {est.theta:.2f}   estimate age {_fmt(age, '.3f')} s   ", "normal"),
         (f"e2e {est.e2e}", "normal" if est.e2e == "ok" else "bad")],
        [],
    ]
    if left_w + 30 > width:
        return []
    out = []
    for i in range(BIG_ROWS):
        out.append([(f" {digits[i]:<{left_w - 1}s}", style + "_bold")] + right[i])
    return out


def _body(snap: MonitorSnapshot, width: int, unicode: bool) -> list[Line]:
    """The screen below the header: MuMax history, wheels, message rates, E2E and input counts."""
    return (_history_lines(snap, width, unicode) + [[]] + _wheel_lines(snap, unicode) + [[]]
            + _message_lines(snap, unicode) + [[]] + _count_lines(snap))


def _history_lines(snap: MonitorSnapshot, width: int, unicode: bool) -> list[Line]:
    hist = snap.history
    if not hist:
        return [[("MuMax history (none yet)", "dim")]]
    lo, hi = min(hist), max(hist)
    if hi - lo < 0.05:
        mid = 0.5 * (hi + lo)
        lo, hi = mid - 0.025, mid + 0.025
    label = f"MuMax history {lo:.2f}..{hi:.2f} "
    n = max(0, width - len(label) - 1)
    spark = sparkline(hist, n, lo, hi, unicode)
    statuses = snap.history_status[-len(spark):] if spark else []
    line: Line = [(label, "dim")]
    # one segment per run of equal status, coloured by that status
    start = 0
    for i in range(1, len(spark) + 1):
        if i == len(spark) or statuses[i] != statuses[start]:
            line.append((spark[start:i], STATUS_STYLE.get(statuses[start], "bad")))
            start = i
    return [line]


def _wheel_lines(snap: MonitorSnapshot, unicode: bool) -> list[Line]:
    lines: list[Line] = [[(f"{'wheel':<6s} {'Slip':>8s} {'MuUsed':>8s} {'MuMaxWheel':>11s} {'NormalForce':>12s}  e2e",
                           "title")]]
    for name, w in zip(WHEELS, snap.wheels):
        if w is None:
            lines.append([(f"{name:<6s} {'—' if unicode else '-':>8s}", "dim")])
            continue
        lines.append([
            (f"{name:<6s} {w.slip:8.4f} {w.mu_used:8.3f} {w.mu_max_wheel:11.4f} {w.normal_force:10.0f} N  ", "normal"),
            (w.e2e, "normal" if w.e2e == "ok" else "bad"),
        ])
    return lines


def _message_lines(snap: MonitorSnapshot, unicode: bool) -> list[Line]:
    rows = list(snap.inputs) + list(snap.outputs)
    name_w = max([len(r.name) + (2 if r.is_output else 0) for r in rows] + [7])
    name_w = min(name_w, 24)
    lines: list[Line] = [[(f"{'message':<{name_w}s} {'ID':>5s} {'age':>9s} {'rate':>10s} {'expected':>9s} "
                           f"{'frames':>9s}", "title")]]
    return lines + [_rate_row(r, name_w, unicode) for r in rows]


def _count_lines(snap: MonitorSnapshot) -> list[Line]:
    e = snap.e2e
    bad = e["crc_failures"] or e["counter_jumps"] or e["frames_lost"]
    undecodable = "; ".join(f"{k} {v}" for k, v in sorted(snap.undecodable.items(), key=lambda kv: -kv[1])[:3])
    rejected = snap.rejected or {}
    rejected_detail = "; ".join(f"{k} {v}" for k, v in sorted(rejected.items(), key=lambda kv: -kv[1])[:4])
    return [
        [("E2E ", "title"),
         (f"ok {e['ok']}   CRC failures {e['crc_failures']}   counter jumps {e['counter_jumps']}   "
          f"frames lost {e['frames_lost']}   repeated {e['repeated']}", "bad" if bad else "normal")],
        [(f"undecodable {snap.undecodable_total}", "bad" if snap.undecodable_total else "normal"),
         (f" ({undecodable})" if undecodable else "", "normal"),
         (f"   other frames {snap.other_frames}   error frames {snap.error_frames}",
          "bad" if snap.error_frames else "normal")],
        [(f"rejected input {sum(rejected.values())}", "warn" if rejected else "normal"),
         (f" ({rejected_detail})" if rejected_detail else "", "normal"),
         (f"   suspect {snap.suspect_share:.1%} of the last second", "normal"),
         (f"   not VALID: {snap.not_valid_reason}" if snap.not_valid_reason else "", "bad")],
    ]


# ---------------------------------------------------------------------------------------------
class _Styles:
    def __init__(self) -> None:
        self.attrs: dict[str, int] = {}
        colours = {"good": curses.COLOR_GREEN, "warn": curses.COLOR_YELLOW, "info": curses.COLOR_CYAN,
                   "stale": curses.COLOR_MAGENTA, "bad": curses.COLOR_RED}
        has = False
        try:
            if curses.has_colors():
                curses.start_color()
                try:
                    curses.use_default_colors()
                    background = -1
                except curses.error:
                    background = curses.COLOR_BLACK
                has = True
        except curses.error:
            has = False
        n = 1
        for name, colour in colours.items():
            base = curses.A_NORMAL
            inverse = curses.A_REVERSE | curses.A_BOLD
            if has:
                try:
                    curses.init_pair(n, colour, background)
                    curses.init_pair(n + 1, curses.COLOR_BLACK, colour)
                    base = curses.color_pair(n)
                    inverse = curses.color_pair(n + 1) | curses.A_BOLD
                except curses.error:
                    pass
                n += 2
            self.attrs[name] = base
            self.attrs[name + "_bold"] = base | curses.A_BOLD
            self.attrs[name + "_inv"] = inverse
        self.attrs.update(normal=curses.A_NORMAL, dim=curses.A_DIM, title=curses.A_BOLD,
                          header=curses.A_REVERSE, bigvalue=curses.A_BOLD)

    def __getitem__(self, name: str) -> int:
        return self.attrs.get(name, curses.A_NORMAL)


def draw(stdscr: Any, lines: list[Line], styles: _Styles) -> None:
    height, width = stdscr.getmaxyx()
    stdscr.erase()
    for y, line in enumerate(lines[:height]):
        x = 0
        for text, style in line:
            room = width - x - (1 if y == height - 1 else 0)  # never write the bottom-right cell
            if room <= 0:
                break
            text = text[:room]
            if text:
                try:
                    stdscr.addstr(y, x, text, styles[style])
                except curses.error:
                    pass
            x += len(text)
    stdscr.noutrefresh()
    curses.doupdate()


def _unicode_ok() -> bool:
    try:
        locale.setlocale(locale.LC_ALL, "")
    except locale.Error:
        pass
    return "UTF" in (locale.getpreferredencoding(False) or "").upper().replace("-", "")


def run(model: MonitorModel, source: Any, waiting_on: str) -> int:
    """The curses loop; returns when `q` is pressed (0)."""
    unicode = _unicode_ok()
    return curses.wrapper(_loop, model, source, waiting_on, unicode)


def _loop(stdscr: Any, model: MonitorModel, source: Any, waiting_on: str, unicode: bool) -> int:
    try:
        curses.curs_set(0)
    except curses.error:
        pass
    stdscr.nodelay(True)
    stdscr.keypad(True)
    styles = _Styles()
    paused = False
    frozen: MonitorSnapshot | None = None
    last_draw = -1.0
    dirty = True
    while True:
        frames = source.poll(POLL_S, time)
        for frame in frames:
            model.feed(frame)
        while True:
            try:
                key = stdscr.getch()
            except curses.error:
                key = -1
            if key == -1:
                break
            dirty = True
            if key in (ord("q"), ord("Q"), 27):
                return 0
            if key in (ord("p"), ord("P"), ord(" ")):
                paused = not paused
                wall = time.monotonic()
                if paused:
                    source.pause(wall)
                    frozen = model.snapshot(source.now(wall), _source_text(source), source.finished)
                else:
                    source.resume(wall)
                    frozen = None
            elif key in (ord("r"), ord("R")):
                model.reset_counters()
                if paused:
                    wall = time.monotonic()
                    frozen = model.snapshot(source.now(wall), _source_text(source), source.finished)
            elif key == curses.KEY_RESIZE:
                try:
                    curses.update_lines_cols()
                except (AttributeError, curses.error):
                    pass
        now = time.monotonic()
        if dirty or now - last_draw >= REDRAW_S:
            if frozen is not None:
                snap = frozen
            else:
                snap = model.snapshot(source.now(now), _source_text(source), source.finished)
            height, width = stdscr.getmaxyx()
            draw(stdscr, render(snap, width, height, paused, unicode, waiting_on), styles)
            last_draw = now
            dirty = False


def _source_text(source: Any) -> str:
    error = getattr(source, "error", None)
    return f"{source.description} ({error})" if error else source.description
