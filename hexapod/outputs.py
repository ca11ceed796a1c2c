"""Where outputs may go: names that become file names, paths that must stay inside their
directory, and files the project may replace.

One rule for every path the project builds from a name (a scenario name, a controller
label, a plugin name): :func:`check_name` where the name enters (a scenario file, a
plugin, a command line), and :func:`inside` where the path is built, before anything is
written. A file is replaced only if the project wrote it (:func:`written_by_project`
recognises the marker every writer puts in its files) or if the user asked for it with an
explicit option (:func:`check_replace`); a directory that holds files of another kind is
refused (:func:`foreign_entries`, :func:`check_output_dir`). See ``docs/outputs.md``.
"""

from __future__ import annotations

import math
import re
import string
import struct
import zlib
from collections.abc import Callable, Iterable
from pathlib import Path

from hexapod.exceptions import OutputError, UnsafeNameError

#: Longest name [characters].
NAME_MAX = 100
#: Characters a name may hold (``:`` and ``.`` for ``module:attr`` controller specs).
NAME_CHARACTERS = frozenset(string.ascii_letters + string.digits + "_.+:-")
#: The rule in words (error messages and docs).
NAME_RULE = (f"a name becomes part of file names: use letters, digits and . _ - + : "
             f"(starting with a letter, a digit or _), at most {NAME_MAX} characters, "
             "no '..'")

#: What every writer of the project puts in its files (HTML meta, PNG text, comments).
GENERATOR = "hexapod-vs"
#: ``savefig(..., metadata=PNG_METADATA)``: the PNG text chunk that marks the project's.
PNG_METADATA = {"Software": GENERATOR}
#: The first line of the project's text files (TOML, Markdown as an HTML comment).
TEXT_MARKER = f"written by {GENERATOR}"
#: The ``<meta>`` tag of the project's HTML pages.
HTML_MARKER = f'<meta name="generator" content="{GENERATOR}">'
#: How much of a file is read to find the project's mark [bytes].
_HEAD = 65536
#: The marks, where the project's writers put them (a file that merely quotes one is not
#: the project's): the PNG text chunk, the HTML ``<meta>`` tag, JSON's first key, and
#: the text mark as a comment of one of the first :data:`_TEXT_LINES` lines.
_PNG_MARK = b"tEXtSoftware\x00" + GENERATOR.encode()
_JSON_MARK = re.compile(rb'\A\s*\{\s*"generator"\s*:\s*"' + re.escape(GENERATOR.encode()) + b'"')
_TEXT_MARK = re.compile(rb"^[ \t]*(?:#|<!--)[ \t]*" + re.escape(TEXT_MARKER.encode()), re.M)
_TEXT_LINES = 5


def check_name(value: object, what: str) -> str:
    """Check a name that will become part of a file name.

    Args:
        value: The name as read (from a file, a plugin, a command line).
        what: What it is, for the message (``"scenario name"``).

    Returns:
        The name.

    Raises:
        UnsafeNameError: Not a string, empty, too long, a separator, ``..``, a NUL or
            control character, or another character outside :data:`NAME_CHARACTERS`.
    """
    if not isinstance(value, str):
        raise UnsafeNameError(what, repr(value), "expected a string")
    if not value:
        raise UnsafeNameError(what, value, "empty; " + NAME_RULE)
    if len(value) > NAME_MAX:
        raise UnsafeNameError(what, value, f"{len(value)} characters; {NAME_RULE}")
    for ch in value:
        if ch in "/\\":
            problem = f"contains the path separator {ch!r}"
        elif ch == "\x00":
            problem = "contains a NUL character"
        elif ord(ch) < 32 or ord(ch) == 127:
            problem = f"contains the control character {ch!r}"
        elif ch not in NAME_CHARACTERS:
            problem = f"contains {ch!r}"
        else:
            continue
        raise UnsafeNameError(what, value, f"{problem}; {NAME_RULE}")
    if ".." in value:
        raise UnsafeNameError(what, value, f"contains '..'; {NAME_RULE}")
    if value[0] not in string.ascii_letters + string.digits + "_":
        raise UnsafeNameError(what, value, f"starts with {value[0]!r}; {NAME_RULE}")
    return value


def inside(directory: str | Path, *parts: str) -> Path:
    """``directory / parts``, refused unless it stays inside ``directory``.

    Args:
        directory: The output directory.
        *parts: Relative path parts (usually built from names).

    Raises:
        OutputError: An absolute part, a ``..`` part, or a path (symbolic links
            resolved) outside ``directory``.
    """
    base = Path(directory)
    path = base.joinpath(*parts)
    for part in parts:
        p = Path(part)
        if p.is_absolute() or ".." in p.parts or "\x00" in part:
            raise OutputError(str(path), f"would be written outside {base}/ (the part "
                              f"{part!r} leaves the directory); nothing was written")
    root = base.resolve()
    if not path.resolve().is_relative_to(root):
        raise OutputError(str(path), f"resolves to {path.resolve()}, outside {root}/ (a "
                          "symbolic link?); nothing was written")
    return path


#: The schema metadata that marks the project's Parquet files
#: (``table.replace_schema_metadata(PARQUET_METADATA)`` before writing; it is in the
#: footer: :func:`written_by_project` asks pyarrow).
PARQUET_METADATA = {b"generator": GENERATOR.encode()}


def written_by_project(path: str | Path) -> bool:
    """Whether a file carries the project's marker (see :data:`GENERATOR`) where the
    project's writers put it (:data:`_TEXT_MARK`...; a user's notes that quote it are
    not the project's), or for a ``.parquet`` file in its schema metadata
    (:data:`PARQUET_METADATA`)."""
    p = Path(path)
    try:
        with p.open("rb") as f:
            head = f.read(_HEAD)
    except OSError:
        return False
    if _PNG_MARK in head or HTML_MARKER.encode() in head or _JSON_MARK.match(head):
        return True
    if head.startswith(b"\xff\xd8\xff\xfe") and TEXT_MARKER.encode() in head[:64]:
        return True  # a JPEG's comment segment (:func:`mark_jpeg`)
    if _TEXT_MARK.search(b"\n".join(head.split(b"\n", _TEXT_LINES)[:_TEXT_LINES])):
        return True
    if p.suffix == ".parquet" and head.startswith(b"PAR1"):
        return _parquet_is_ours(p)
    return False


def _parquet_is_ours(path: Path) -> bool:
    try:
        import pyarrow.parquet as pq

        meta = pq.read_schema(path).metadata or {}
    except Exception:  # no pyarrow, or not a readable Parquet file: not ours
        return False
    return bool(meta.get(b"generator") == PARQUET_METADATA[b"generator"])


#: The files of a run directory that carry no mark (the run's own): a refusal to replace
#: one says so, not that the project did not write it.
RUN_FILES = ("run.json", "results.jsonl")


def _describe(path: Path) -> str:
    if path.is_dir():
        return "a directory"
    if path.name in RUN_FILES and (path.parent / RUN_FILES[1]).exists():
        return f"the {path.name} of the run in {path.parent}, which this command does not replace"
    try:
        size = path.stat().st_size
    except OSError:
        return "a file"
    kind = f"a {path.suffix} file" if path.suffix else "a file"
    return f"{kind} of {size} bytes, not written by {GENERATOR}"


def check_replace(path: str | Path, overwrite: bool = False, option: str = "--overwrite",
                  ours: Callable[[Path], bool] | None = None, how: str | None = None,
                  kind: str | None = None) -> None:
    """Refuse to replace an existing file the project did not write, unless asked to.

    Args:
        path: The file about to be written.
        overwrite: The user asked explicitly (``option`` given).
        option: The option that asks, for the message.
        ours: Recognises the project's files of this kind (default
            :func:`written_by_project`).
        how: How to proceed, for the message (default: another name or ``option``).
        kind: What is about to be written (:func:`file_kind`): a project's file of
            another kind is refused too (a ``--json`` given a run's ``report.md``).

    Raises:
        OutputError: ``path`` is a directory, or a file neither the project's (of
            ``kind``) nor ``overwrite`` (naming what it is and how to proceed).
    """
    p = Path(path)
    if p.is_dir():
        raise OutputError(str(p), "is a directory; give a file name")
    if not p.exists() or overwrite:
        return
    how = how or f"choose another name, or add {option} to replace it"
    if (ours or written_by_project)(p):
        there = file_kind(p) if kind is not None else None
        if there is None or there == kind:
            return
        raise OutputError(str(p), f"already exists ({GENERATOR}'s {there}, and this writes "
                          f"a {kind} file); {how}")
    raise OutputError(str(p), f"already exists ({_describe(p)}); {how}")


def file_kind(source: str | Path | bytes, suffix: str = "") -> str | None:
    """The kind of a file the project writes: ``"PNG"``, ``"JPEG"``, ``"Parquet"`` or
    ``"JSON"`` from its first bytes, else ``"Markdown"``, ``"HTML"``, ``"TOML"`` or
    ``"JSON lines"`` from its marker or its name's suffix, or None (none the project
    can tell).

    Args:
        source: A file, or the bytes about to be written.
        suffix: The name's suffix of bytes (a path gives its own).
    """
    if isinstance(source, bytes):
        head = source[:_HEAD]
    else:
        suffix = Path(source).suffix
        try:
            with Path(source).open("rb") as f:
                head = f.read(_HEAD)
        except OSError:
            return None
    for kind, magic in (("PNG", b"\x89PNG\r\n\x1a\n"), ("JPEG", b"\xff\xd8"),
                        ("Parquet", b"PAR1")):
        if head.startswith(magic):
            return kind
    text = head.lstrip()
    if text.startswith(MARKDOWN_MARKER.encode()):
        return "Markdown"
    if text.startswith((HTML_MARKER.encode(), b"<!DOCTYPE html", b"<!doctype html", b"<html")):
        return "HTML"
    if suffix != ".jsonl" and text.startswith((b"{", b"[")):
        return "JSON"
    return _SUFFIX_KINDS.get(suffix.lower())


#: The kinds of the project's text files that their name tells (:func:`file_kind`).
_SUFFIX_KINDS = {".md": "Markdown", ".markdown": "Markdown", ".html": "HTML", ".htm": "HTML",
                 ".toml": "TOML", ".json": "JSON", ".jsonl": "JSON lines"}


def foreign_entries(directory: str | Path, own: Callable[[Path], bool]) -> list[Path]:
    """The entries of a directory that ``own`` does not recognise (sorted)."""
    d = Path(directory)
    if not d.is_dir():
        return []
    return sorted(e for e in d.iterdir() if not own(e))


def listing(entries: Iterable[Path], limit: int = 8) -> str:
    """``a.md, b.txt (and 3 more)``: what a refused directory holds."""
    names = [e.name + ("/" if e.is_dir() else "") for e in entries]
    text = ", ".join(names[:limit])
    return text + (f" (and {len(names) - limit} more)" if len(names) > limit else "")


def check_output_dir(directory: str | Path, own: Callable[[Path], bool], kind: str,
                     overwrite: bool = False, proceed: str = "") -> None:
    """Refuse a directory that holds entries a command did not write, unless asked to.

    Args:
        directory: The output directory (absent or empty: fine).
        own: Recognises the entries the command writes.
        kind: What the command's directories are (``"run directory"``).
        overwrite: The user gave ``--overwrite``.
        proceed: Extra ways to proceed, for the message.

    Raises:
        OutputError: A file where the directory should be, or foreign entries.
    """
    d = Path(directory)
    if d.exists() and not d.is_dir():
        raise OutputError(str(d), "is a file, not a directory; choose another --out")
    foreign = foreign_entries(d, own)
    if foreign and not overwrite:
        raise OutputError(str(d), f"is not empty and is not a {kind}: it holds "
                          f"{listing(foreign)}; choose another --out{proceed}, or add "
                          "--overwrite to write into it anyway (files of the same names "
                          "are replaced, the others are left alone)")


def mark_png(data: bytes) -> bytes:
    """PNG bytes with the project's text chunk (``Software: hexapod-vs``) after the header.

    For PNG writers that take no metadata (OpenCV's ``imencode``). Already marked: the
    bytes as they are. A writer that puts its own ``Software`` chunk (matplotlib) is
    given :data:`PNG_METADATA` instead: a reader keeps one ``Software`` per file.
    """
    sig, ihdr_end = b"\x89PNG\r\n\x1a\n", 8 + 4 + 4 + 13 + 4
    if not data.startswith(sig):
        raise ValueError("not a PNG")
    if b"tEXtSoftware\x00" + GENERATOR.encode() in data:
        return data  # marked already (matplotlib's savefig(metadata=PNG_METADATA))
    body = b"tEXt" + b"Software\x00" + GENERATOR.encode()
    chunk = struct.pack(">I", len(body) - 4) + body + struct.pack(">I", zlib.crc32(body))
    return data[:ihdr_end] + chunk + data[ihdr_end:]


#: The first line of the project's Markdown files (an HTML comment: invisible once
#: rendered).
MARKDOWN_MARKER = f"<!-- {TEXT_MARKER} -->"


def mark_jpeg(data: bytes) -> bytes:
    """JPEG bytes with a comment segment ``written by hexapod-vs`` after the start marker."""
    if not data.startswith(b"\xff\xd8"):
        raise ValueError("not a JPEG")
    text = TEXT_MARKER.encode()
    return data[:2] + b"\xff\xfe" + struct.pack(">H", len(text) + 2) + text + data[2:]


def json_signed(value: object) -> object:
    """``value`` as standard JSON takes it, recursively: NaN as None, an infinity as the
    string ``"inf"`` or ``"-inf"`` (its sign kept; ``float()`` reads it back)."""
    return _json_clean(value, signed_inf=True)


def _json_clean(value: object, signed_inf: bool) -> object:
    """``value`` with every non-finite float replaced, recursively: NaN as None, an
    infinity as ``"inf"``/``"-inf"`` when ``signed_inf`` and as None otherwise."""
    if isinstance(value, float):  # (numpy's float64 too)
        x = float(value)
        if math.isfinite(x):
            return x
        return ("inf" if x > 0 else "-inf") if signed_inf and math.isinf(x) else None
    if isinstance(value, dict):
        return {k: _json_clean(v, signed_inf) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_clean(v, signed_inf) for v in value]
    return value


_JSON_SCALARS = (str, int, float, bool, type(None))


def _not_json(value: object, where: str) -> tuple[str, str] | None:
    """The first value (or dict key) of ``value`` that ``json.dumps`` cannot write, as
    ``(what, type name)`` (``what``: ``the value at 'a.b[2]'``, ``the key (1, 2) in 'a'``);
    None when every value can be written. Only called once ``json.dumps`` has failed.

    Args:
        value: The content, NaN and infinities already replaced.
        where: The place of ``value`` in the content (empty: the content itself).
    """
    if isinstance(value, dict):
        for k, v in value.items():
            inner = f"{where}.{k}" if where else str(k)
            if not isinstance(k, _JSON_SCALARS):
                return f"the key {k!r}" + (f" in {where!r}" if where else ""), type(k).__name__
            found = _not_json(v, inner)
            if found is not None:
                return found
        return None
    if isinstance(value, list | tuple):
        for i, v in enumerate(value):
            found = _not_json(v, f"{where}[{i}]")
            if found is not None:
                return found
        return None
    if isinstance(value, _JSON_SCALARS):
        return None
    return (f"the value at {where!r}" if where else "the content"), type(value).__name__


def _marked(path: Path, content: object) -> bytes:
    """The bytes of an output with the project's mark, by kind of content."""
    import json

    if isinstance(content, dict | list):
        doc = ({"generator": GENERATOR, **content} if isinstance(content, dict)
               else {"generator": GENERATOR, "items": content})
        # NaN and infinities as null: json.dumps would write NaN / Infinity, not JSON
        clean = _json_clean(doc, signed_inf=False)
        try:
            text = json.dumps(clean, indent=1, allow_nan=False)
        except (TypeError, ValueError) as exc:  # a value JSON has no form for
            found = _not_json(clean, "")
            what = f"{found[0]} has type {found[1]}" if found is not None else str(exc)
            raise OutputError(str(path), f"cannot be written as JSON: {what} (convert it: "
                              "a list, a float, a str); nothing was written") from None
        return (text + "\n").encode()
    if isinstance(content, bytes):
        if content.startswith(b"\x89PNG\r\n\x1a\n"):
            return mark_png(content)
        if content.startswith(b"\xff\xd8"):
            return mark_jpeg(content)
        raise ValueError(f"{path}: bytes of an unknown kind (PNG or JPEG expected)")
    if isinstance(content, str):
        if path.suffix in (".md", ".markdown", ".html", ".htm"):
            mark = HTML_MARKER if path.suffix.startswith(".htm") else MARKDOWN_MARKER
            return (mark + "\n" + content).encode()
        if path.suffix == ".toml":
            return (f"# {TEXT_MARKER}\n" + content).encode()
        raise ValueError(f"{path}: no mark for a text file of this kind (.md, .html, .toml)")
    if hasattr(content, "schema") and hasattr(content, "replace_schema_metadata"):
        import io

        import pyarrow.parquet as pq

        meta = {**(content.schema.metadata or {}), **PARQUET_METADATA}
        buf = io.BytesIO()
        pq.write_table(content.replace_schema_metadata(meta), buf)
        return buf.getvalue()
    raise TypeError(f"{path}: cannot write a {type(content).__name__}")


def write_output(path: str | Path, content: object, overwrite: bool = False,
                 option: str = "--overwrite") -> Path:
    """Write one output file the project's way (``docs/outputs.md``): a file the project
    did not write is refused unless ``overwrite``, the file carries the project's mark,
    its folder is created, and it is replaced whole (written beside it, then renamed).

    Args:
        path: The file.
        content: A dict (JSON, with a ``"generator"`` key first; a list goes under
            ``"items"``), PNG or JPEG bytes (a text chunk ``Software``, a comment
            segment), a ``str`` for a ``.md`` (first line an HTML comment), ``.html``
            (a ``<meta name="generator">``) or ``.toml`` file (a first-line comment), or
            a ``pyarrow.Table`` (Parquet, ``generator`` in the schema metadata).
        overwrite: The user gave ``option``.
        option: The option that allows replacing a user's file, for the message.

    Returns:
        The path written.

    Raises:
        OutputError: An existing file the project did not write (without
            ``overwrite``), or a directory; a folder that cannot be made (a file
            where a folder of the path should be), a file that cannot be written, a
            dict or list with a value JSON cannot hold (naming the key and its type).
            Nothing is written.
        ValueError: Bytes that are neither PNG nor JPEG, or a ``str`` for a file of
            another kind than ``.md``, ``.html`` or ``.toml``.
        TypeError: Content of none of the kinds above.
    """
    p = Path(path)
    data = _marked(p, content)
    check_replace(p, overwrite, option, kind=file_kind(data, p.suffix))
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(str(p), f"its folder cannot be made: {_folder_problem(p, exc)}; "
                          "nothing was written") from None
    return replace_whole(p, data)


def _folder_problem(path: Path, exc: OSError) -> str:
    """Why the folder of ``path`` could not be made: a file where one of its folders
    should be (the nearest existing part of the path), or the system's reason."""
    for part in path.parents:
        if part.exists() or part.is_symlink():
            if not part.is_dir():
                return f"{part} is a file, not a folder"
            break
    return f"{exc.strerror or exc}" + (f" ({exc.filename})" if exc.filename else "")


def replace_whole(path: str | Path, data: bytes | str) -> Path:
    """Write ``data`` to ``path`` whole or not at all: beside it, then renamed over it
    (a full disk or a kill leaves the earlier file, never a cut one).

    Raises:
        OutputError: The file could not be written (a full disk, no permission), naming
            it and the system's reason.
    """
    p = Path(path)
    tmp = p.with_name(f".{p.name}.part")
    try:
        if isinstance(data, str):
            tmp.write_text(data, encoding="utf-8")
        else:
            tmp.write_bytes(data)
        tmp.replace(p)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise OutputError(str(p), f"could not be written ({exc.strerror or exc}); the "
                          "file there before, if any, is unchanged") from exc
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return p
