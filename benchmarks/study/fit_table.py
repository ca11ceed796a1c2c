"""Tables that fit the terminal: no cell is ever cut to ``0.…``.

A table wider than the console is printed in column groups: each group repeats the key
columns (sweep, controller...) and takes as many of the other columns as fit; key
columns whose value is the same in every row go to the title instead. When even the keys
and one other column do not fit, each row is printed as a block of ``column: value``
lines (the narrow layout). Every cell keeps its whole text in every layout.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

#: Characters a column adds to its cells' width: one space of padding on each side and
#: its right border (rich's default box with ``show_edge``).
COLUMN_EXTRA = 3


def _lines(header: str, width: int) -> int:
    """Lines of a header wrapped at word boundaries to ``width`` characters."""
    lines, used = 1, -1
    for word in header.split():
        if used + 1 + len(word) > width and used >= 0:
            lines, used = lines + 1, len(word)
        else:
            used += 1 + len(word)
    return lines


def _need(header: str, cells: Sequence[str], header_lines: int, wrap: bool = False) -> int:
    """Width a column needs: its widest cell (its longest word when ``wrap``: a sweep
    ``a=1, b=2`` may wrap after a comma, no other cell wraps), and its header on at most
    ``header_lines`` lines (wrapped at words)."""
    longest = [max([len(w) for w in c.split()] or [0]) if wrap else len(c) for c in cells]
    width = max([max([len(w) for w in header.split()] or [0]), *longest])
    while _lines(header, width) > header_lines:
        width += 1
    return width


def table_width(widths: Sequence[int]) -> int:
    """Characters of a rich table with columns of these content widths."""
    return 1 + sum(w + COLUMN_EXTRA for w in widths)


def column_groups(widths: Sequence[int], keys: Sequence[int], width: int
                  ) -> list[list[int]] | None:
    """Split the columns into groups that fit ``width``, each with the key columns first.

    Args:
        widths: Content width of every column.
        keys: Indices of the key columns (repeated in every group).
        width: The console's width.

    Returns:
        The column indices of each group (one group when the table fits), or None when
        the keys and any one other column do not fit together.
    """
    if table_width(widths) <= width:
        return [list(range(len(widths)))]
    base = [widths[k] for k in keys]
    groups: list[list[int]] = []
    current: list[int] = []
    for i in (i for i in range(len(widths)) if i not in keys):
        if table_width([*base, widths[i]]) > width:
            return None
        if table_width([*base, *(widths[j] for j in current), widths[i]]) > width:
            groups.append(current)
            current = []
        current.append(i)
    if current:
        groups.append(current)
    return [[*keys, *g] for g in groups]


def print_table(con: Any, title: str, header: Sequence[str], rows: Sequence[Sequence[str]],
                keys: Sequence[int] = (), left: Sequence[int] = (),
                escape_cells: bool = False, wrap: Sequence[int] = ()) -> None:
    """Print a table that fits ``con.width`` without cutting a cell.

    Args:
        con: A rich console.
        title: The table's title.
        header: Column names.
        rows: Cells (text).
        keys: Indices of the columns that name a row (repeated in every column group;
            moved to the title when every row has the same value).
        left: Indices of the left-justified columns (the others are right-justified).
        escape_cells: Escape rich markup in the cells (brackets in intervals, sweeps).
        wrap: Indices of the columns whose cells may wrap at their spaces when the table
            does not fit otherwise (a sweep ``a=1, b=2``: every value stays whole).
    """
    from rich.markup import escape
    from rich.table import Table
    from rich.text import Text

    cells = [[escape(c) if escape_cells else c for c in r] for r in rows]
    constant = [k for k in keys if len(rows) > 1 and len({r[k] for r in rows}) == 1]
    said = [k for k in constant if rows[0][k] not in ("", "-")]
    if said:
        title += " - " + ", ".join(f"{header[k]}: {rows[0][k]}" for k in said)
    shown = [i for i in range(len(header)) if i not in constant]
    key_pos = [shown.index(k) for k in keys if k in shown]
    # the headers on one line if the table fits, else wrapped; then the wrapping cells
    for lines, wrapping in ((1, False), (2, False), (99, False), (99, True)):
        widths = [_need(header[i], [r[i] for r in rows], lines, wrapping and i in wrap)
                  for i in shown]
        groups = column_groups(widths, key_pos, int(con.width))
        if groups is not None and (len(groups) == 1 or lines == 99):
            break
    if groups is None:
        _print_blocks(con, title, header, rows, shown, [shown[k] for k in key_pos])
        return
    for n, group in enumerate(groups):
        part = f" ({n + 1}/{len(groups)})" if len(groups) > 1 else ""
        t = Table(title=Text(title + part))  # a path or a sweep is not markup
        for j in group:
            i = shown[j]
            t.add_column(header[i], justify="left" if i in left else "right",
                         width=widths[j])
        for r in cells:
            t.add_row(*(r[shown[j]] for j in group))
        con.print(t)


def _print_blocks(con: Any, title: str, header: Sequence[str], rows: Sequence[Sequence[str]],
                  shown: list[int], keys: list[int]) -> None:
    """The narrow layout: one block per row, its keys on a line, then one line per
    other column."""
    con.print(title, markup=False, highlight=False)
    for r in rows:
        con.print("- " + ", ".join(r[k] for k in keys), markup=False, highlight=False)
        for i in shown:
            if i not in keys:
                con.print(f"    {header[i]}: {r[i]}", markup=False, highlight=False)
