"""The CSV tables of a bundle, read as the spec says: comma-separated, one header row.

:func:`read_rows` is the one reader of every table (coupon curves, grids, lab measurements):
its size is checked before it is read (:func:`fenicsx_drape.limits.check_table_size`), ``#``
comment lines before the header are skipped, cells may be quoted (``"force_N"``, ``"1.5"``),
and a table separated by semicolons or tabs (a spreadsheet's export with decimal commas) is
refused as such, not read as one column of unknown name. Problems go to ``add(file, line,
problem)`` with the file's line.
"""

from __future__ import annotations

import csv
from collections.abc import Callable
from pathlib import Path

from fenicsx_drape.errors import DrapeInputError

Add = Callable[[str, int, str], None]
SEPARATORS = {";": "semicolons", "\t": "tabs", "|": "bars"}


def read_rows(path: Path, label: str, add: Add
              ) -> tuple[list[str], int, list[tuple[int, list[str]]]] | None:
    """The header, its line and the data rows ``(line, cells)`` of a CSV table.

    None (the problem given to ``add``) when the table is too large, cannot be read, has no
    header or is not comma-separated.
    """
    from fenicsx_drape.limits import check_table_size

    fname = str(path)
    try:
        check_table_size(path)
        text = path.read_text(encoding="utf-8-sig")
    except DrapeInputError as err:
        add(fname, 0, f"{label}: {str(err).removeprefix(fname + ': ')}")
        return None
    except (OSError, UnicodeDecodeError) as err:
        add(fname, 0, f"{label}: cannot read the table (not a CSV text file?): {err}")
        return None
    header, header_line, rows = None, 0, []
    for number, raw in enumerate(text.splitlines(), start=1):
        stripped = raw.strip()
        if not stripped:
            continue
        if header is None:
            if stripped.startswith("#"):
                continue
            header, header_line = _cells(stripped), number
            if len(header) == 1 and (sep := next((s for s in SEPARATORS if s in stripped),
                                                 None)):
                add(fname, number, f"{label}: the table's columns are separated by "
                                   f"{SEPARATORS[sep]} ({stripped[:60]!r}); a table's columns "
                                   "are separated by commas, numbers written with a decimal "
                                   "point (1.5, not 1,5)")
                return None
            continue
        rows.append((number, _cells(stripped)))
    if header is None:
        add(fname, 0, f"{label}: the table has no header row")
        return None
    return header, header_line, rows


def _cells(line: str) -> list[str]:
    """The cells of one line: comma-separated, quotes allowed, blanks around a cell dropped."""
    if '"' not in line:
        return [c.strip() for c in line.split(",")]
    return [c.strip() for c in next(csv.reader([line], skipinitialspace=True))]


def ragged_hint(cells: list[str]) -> str:
    """A hint for a row whose cells do not match the header: another separator in it."""
    for sep, name in SEPARATORS.items():
        if any(sep in c for c in cells):
            return f" (separated by {name}? the columns are separated by commas)"
    return ""
