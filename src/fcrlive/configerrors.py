"""One-line messages for pydantic validation errors of configuration files, in the user's words.

Every file fcrlive reads through a pydantic model (the daemon's configuration, Modbus register maps)
reports its problems as ``(key path, message)`` (:func:`explain`: the first, :func:`explain_all`: all),
e.g. ``("source.modbus.poll_hz", "must be between 10 and 50 (got 80)")``; the caller prefixes the file
name and raises :class:`fcrlive.errors.ConfigError`.
"""

from __future__ import annotations

from typing import Any

import annotated_types
from pydantic import BaseModel, ValidationError

from fcrlive.errors import ConfigError


def _loc_str(loc: tuple) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out


def _field_info(model: type[BaseModel], loc: tuple):
    """The FieldInfo at ``loc`` (skipping list indices), or None."""
    info = None
    cur: Any = model
    for part in loc:
        if isinstance(part, int):
            continue
        if not (isinstance(cur, type) and issubclass(cur, BaseModel)) or part not in cur.model_fields:
            return None
        info = cur.model_fields[part]
        cur = _inner_model(info.annotation)
    return info


def _inner_model(annotation: Any) -> Any:
    """The BaseModel inside ``X``, ``X | None`` or ``list[X]``, else the annotation itself."""
    args = getattr(annotation, "__args__", ())
    for a in (annotation, *args):
        if isinstance(a, type) and issubclass(a, BaseModel):
            return a
        for b in getattr(a, "__args__", ()):
            if isinstance(b, type) and issubclass(b, BaseModel):
                return b
    return annotation


def _bounds_message(info, got: Any) -> str | None:
    lo = hi = None
    lo_incl = hi_incl = True
    for m in info.metadata if info else ():
        if isinstance(m, annotated_types.Ge):
            lo = m.ge
        elif isinstance(m, annotated_types.Gt):
            lo, lo_incl = m.gt, False
        elif isinstance(m, annotated_types.Le):
            hi = m.le
        elif isinstance(m, annotated_types.Lt):
            hi, hi_incl = m.lt, False
    if lo is None and hi is None:
        return None
    if lo is not None and hi is not None and lo_incl and hi_incl:
        return f"must be between {lo:g} and {hi:g} (got {got})"
    parts = []
    if lo is not None:
        parts.append(f"{'≥' if lo_incl else '>'} {lo:g}")
    if hi is not None:
        parts.append(f"{'≤' if hi_incl else '<'} {hi:g}")
    return f"must be {' and '.join(parts)} (got {got})"


def explain(exc: ValidationError, model: type[BaseModel]) -> tuple[str, str]:
    """``(key path, message)`` for the first error of ``exc``: short, in the user's words."""
    return _explain_one(exc.errors(include_url=False)[0], model)


def explain_all(exc: ValidationError, model: type[BaseModel]) -> list[tuple[str, str]]:
    """``(key path, message)`` for every error of ``exc``, one per key (a key that fails several ways,
    e.g. each member of a union, keeps its first message), in the order pydantic found them."""
    out: dict[str, str] = {}
    for err in exc.errors(include_url=False):
        key, msg = _explain_one(err, model)
        out.setdefault(key, msg)
    return list(out.items())


def _explain_one(err: Any, model: type[BaseModel]) -> tuple[str, str]:
    loc = tuple(err["loc"])
    kind = err["type"]
    got = err.get("input")
    got_s = repr(got) if isinstance(got, str) else str(got)
    if kind == "extra_forbidden":
        return _loc_str(loc), "unknown key"
    if kind == "missing":
        return _loc_str(loc), "required key missing"
    if kind in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
        msg = _bounds_message(_field_info(model, loc), got)  # env values arrive as strings: no quotes
        if msg:
            return _loc_str(loc), msg
    msg = err["msg"]
    for prefix in ("Value error, ", "Assertion failed, "):
        msg = msg.removeprefix(prefix)
    msg = msg.replace("Input should be", "must be").replace("Input should", "must")
    msg = msg[:1].lower() + msg[1:]
    if kind != "value_error" and not isinstance(got, dict | list):
        msg += f" (got {got_s})"
    return _loc_str(loc), msg




def decode_config_text(data: bytes, where: str) -> str:
    """The text of a configuration file (TOML is UTF-8), or ConfigError naming ``where`` and what the
    bytes look like instead: UTF-16 (a byte-order mark or NUL bytes between ASCII letters, as Windows
    editors save "Unicode") or binary."""
    if data.startswith(b"\xef\xbb\xbf"):
        data = data[3:]  # a UTF-8 byte-order mark is harmless
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        text = None
        why = f"byte 0x{data[exc.start]:02x} at offset {exc.start}"
    else:
        why = "a NUL byte"
    if text is not None and "\x00" not in text:
        return text
    head = data[:256]
    nul_share = max(head[1::2].count(0), head[0::2].count(0)) / max(1, len(head))
    if head.startswith((b"\xff\xfe", b"\xfe\xff")) or (len(head) >= 4 and nul_share > 0.25):
        hint = "looks like UTF-16: save it as UTF-8"
    else:
        hint = "looks binary: is this the right file?"
    raise ConfigError(f"not a UTF-8 text file ({why}); {hint}", where=where)
