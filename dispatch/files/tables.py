"""Table files (CSV, Parquet) read into columns: the checks before a file is read (a regular
file, not too large, UTF-8 text) and :class:`Table`, which converts the columns a reader asks
for into number arrays (a CSV file of numbers by pyarrow, any other row by row in chunks), a
bad cell named by its 1-based data row.

The rules are the ``csv`` module's (``csv.DictReader``'s): blank lines skipped, a short row's
missing cells blank (None), a repeated column name meaning its last column; numbers are what
Python's ``float()`` reads.
"""

from __future__ import annotations

import codecs
import csv
import io
import math
import operator
import os
import stat
from pathlib import Path

import numpy as np

from dispatch.errors import ScenarioError

#: byte order marks of encodings other than UTF-8 (longest first: UTF-32 LE starts as UTF-16 LE)
BOMS = ((codecs.BOM_UTF32_LE, "UTF-32 LE"), (codecs.BOM_UTF32_BE, "UTF-32 BE"),
        (codecs.BOM_UTF16_LE, "UTF-16 LE"), (codecs.BOM_UTF16_BE, "UTF-16 BE"))


def check_file(path: Path, max_bytes: int | None, what: str = "file") -> int:
    """Stat ``path`` before reading it: it must exist, be a regular file (not a device, a
    FIFO or a folder) and hold at most ``max_bytes`` (None: no bound). Returns its size."""
    try:
        st = os.stat(path)
    except OSError as e:
        reason = "cannot be read: file not found" if isinstance(e, FileNotFoundError) else \
            f"cannot be read ({e.strerror or e})"
        raise ScenarioError(path, "<file>", reason) from None
    if not stat.S_ISREG(st.st_mode):
        kind = "a folder" if stat.S_ISDIR(st.st_mode) else "a device, pipe or socket"
        raise ScenarioError(path, "<file>", f"is {kind}, not a regular {what}")
    if max_bytes is not None and st.st_size > max_bytes:
        raise ScenarioError(path, "<file>", f"is {st.st_size / 2**20:.1f} MiB; a {what} of "
                                            f"more than {max_bytes / 2**20:.0f} MiB is refused "
                                            "(use --ignore-limits to read it anyway)")
    return st.st_size


def read_bytes(path: Path, max_bytes: int | None, what: str = "file") -> bytes:
    """The bytes of a regular file checked by :func:`check_file` (read at most the size it
    had, plus one byte: a file that grows meanwhile is refused, not read without end)."""
    size = check_file(path, max_bytes, what)
    try:
        with open(path, "rb") as fh:
            data = fh.read(size + 1 if max_bytes is None else max(size, max_bytes) + 1)
    except OSError as e:
        raise ScenarioError(path, "<file>", f"cannot be read ({e.strerror or e})") from None
    if max_bytes is not None and len(data) > max_bytes:
        raise ScenarioError(path, "<file>", f"grew past {max_bytes / 2**20:.0f} MiB while read")
    return data


def decode_text(path: Path, data: bytes) -> str:
    """UTF-8 text (a UTF-8 byte order mark is dropped); one-line errors for a UTF-16/32 file
    (named by its byte order mark) and for bytes that are not UTF-8."""
    for bom, name in BOMS:
        if data.startswith(bom):
            raise ScenarioError(path, "<encoding>", f"is {name} text (it starts with the byte "
                                                    f"order mark {bom.hex(' ').upper()}); save "
                                                    "it as UTF-8")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = data[: e.start].count(b"\n") + 1
        raise ScenarioError(path, "<encoding>", f"is not UTF-8 text (byte 0x{data[e.start]:02X} "
                                                f"on line {line}, offset {e.start}); save it "
                                                "as UTF-8") from None


#: rows converted at a time while a CSV file is read (the cells of one chunk are held as
#: strings; the file's columns only as numbers)
CHUNK_ROWS = 32_768
#: what :meth:`Table.read` makes of a column: numbers (a blank cell is an error), numbers where
#: a blank cell is nan, or the cells as read (date-times: parsed by the caller)
NUMBER, NUMBER_OR_BLANK, CELLS = "number", "number_or_blank", "cells"


def _cell_number(path: Path, name: str, i: int, v, blank_ok: bool) -> float:
    """One cell as a float (nan for a blank one where ``blank_ok``); a bad one names its
    1-based data row (``i`` is 0-based)."""
    if blank_ok and (v is None or (isinstance(v, str) and not v.strip())):
        return math.nan
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise ScenarioError(path, f"row {i + 1}", f"{name} is not a number ({v!r})") from None
    if not math.isfinite(f):
        raise ScenarioError(path, f"row {i + 1}", f"{name} is not finite ({v!r})")
    return f


def _longest_line(data: bytes) -> int:
    """Bytes in the longest line of ``data`` (lines end at ``\\n`` or ``\\r``)."""
    if len(data) <= csv.field_size_limit():
        return len(data)  # (short enough whatever its lines)
    arr = np.frombuffer(data, np.uint8)
    longest, last, block = 0, -1, 1 << 23
    for at in range(0, arr.size, block):
        part = arr[at:at + block]
        ends = np.flatnonzero((part == 10) | (part == 13)) + at
        if ends.size:
            longest = max(longest, int(ends[0] - last - 1), int(np.diff(ends).max(initial=0)) - 1)
            last = int(ends[-1])
    return max(longest, arr.size - last - 1)


class Columns:
    """The columns :meth:`Table.read` converted: numbers as float arrays, cells as lists. A
    column's first bad cell is kept (not raised) until the column is asked for, so that the
    error a reader sees is the one of the first column it checks, whatever the rows' order."""

    def __init__(self, path: Path, n: int, numbers: dict[str, np.ndarray],
                 cells: dict[str, list], errors: dict[str, ScenarioError]) -> None:
        self.path, self.n = path, n
        self._numbers, self._cells, self._errors = numbers, cells, errors

    def numbers(self, names) -> np.ndarray:
        """The named columns as a float array ``(rows, len(names))``; the first bad cell of the
        first column (in ``names``' order) that has one raises its ScenarioError."""
        for name in names:
            if name in self._errors:
                raise self._errors[name]
        if not names:
            return np.empty((self.n, 0))
        return np.column_stack([self._numbers[name] for name in names])

    def cells(self, name: str) -> list:
        """The cells of a column read as :data:`CELLS`."""
        return self._cells[name]


class Table:
    """A CSV or Parquet table file, its header read: :attr:`names` are its columns, and
    :meth:`read` converts the columns asked for. A CSV file is read in chunks of rows, so a
    large trace is held as arrays of numbers, never as a string per cell (the parsing rules
    are the ``csv`` module's: blank lines skipped, a short row's missing cells blank, a
    repeated column name meaning its last column)."""

    def __init__(self, path: Path, max_bytes: int | None = None) -> None:
        check_file(path, max_bytes, "table file")
        self.path = path
        suffix = path.suffix.lower()
        if suffix not in (".csv", ".parquet"):
            raise ScenarioError(path, "<file>", "must be a .csv or .parquet file")
        self._arrow = None
        self._rows = None
        self._data = b""
        try:
            if suffix == ".parquet":
                import pyarrow.parquet as pq

                self._arrow = pq.read_table(path)
                self.names = list(self._arrow.column_names)
            else:
                data = read_bytes(path, max_bytes, "table file")
                decode_text(path, data)  # the encoding checks; the text is read again in rows
                self._data = data
                self._rows = csv.reader(io.TextIOWrapper(io.BytesIO(data), encoding="utf-8-sig",
                                                         newline=""))
                self.names = next(self._rows, None) or []
        except ScenarioError:
            raise
        except Exception as e:  # pyarrow and csv raise several kinds for a malformed file
            raise ScenarioError(path, "<file>", f"cannot be read as a table: {e}") from None

    def read(self, want: dict[str, str]) -> Columns:
        """Read the rows, converting each column of ``want`` (a column of the header, by
        name) as its kind says (:data:`NUMBER`, :data:`NUMBER_OR_BLANK`, :data:`CELLS`). A
        CSV file's rows are read once: ``read({})`` only checks that the rest of the file
        parses."""
        try:
            if self._arrow is not None:
                return self._read_arrow(want)
            return self._read_csv_at_once(want) or self._read_csv(want)
        except ScenarioError:
            raise
        except Exception as e:  # pyarrow and csv raise several kinds for a malformed file
            raise ScenarioError(self.path, "<file>", f"cannot be read as a table: {e}") from None

    def _read_arrow(self, want: dict[str, str]) -> Columns:
        import pyarrow as pa

        numbers, cells, errors = {}, {}, {}
        n = self._arrow.num_rows
        for name, kind in want.items():
            col = self._arrow.column(name)
            if kind == CELLS:
                cells[name] = col.to_pylist()
                continue
            if (pa.types.is_integer(col.type) or pa.types.is_floating(col.type)) \
                    and col.null_count == 0:
                values = numbers_of(col).astype(np.float64)
                if np.isfinite(values).all():
                    numbers[name] = values
                    continue
            numbers[name] = self._slow(name, col.to_pylist(), 0, kind == NUMBER_OR_BLANK,
                                       errors)
        return Columns(self.path, n, numbers, cells, errors)

    def _slow(self, name: str, values, first: int, blank_ok: bool,
              errors: dict[str, ScenarioError]) -> np.ndarray:
        """Cell by cell (rows ``first``, ``first + 1``, ...); a bad cell is nan, the column's
        first one kept in ``errors``."""
        out = np.empty(len(values))
        for i, v in enumerate(values, first):
            try:
                out[i - first] = _cell_number(self.path, name, i, v, blank_ok)
            except ScenarioError as e:
                errors.setdefault(name, e)
                out[i - first] = math.nan
        return out

    def _read_csv_at_once(self, want: dict[str, str]) -> Columns | None:
        """The columns of ``want`` read by pyarrow's CSV reader, where the file is one it
        reads as the ``csv`` module does and every cell of them is a finite number; None
        otherwise (the file is then read row by row, for the same result or the error of the
        cell or row at fault). :data:`CELLS` columns are read as strings, as written."""
        if not want or len(set(self.names)) != len(self.names) or b"\0" in self._data \
                or _longest_line(self._data) >= csv.field_size_limit():
            return None  # (the csv module refuses a NUL byte and a field past its limit)
        import pyarrow as pa
        import pyarrow.csv as pc

        try:
            table = pc.read_csv(
                io.BytesIO(self._data),
                read_options=pc.ReadOptions(use_threads=False),  # as fast here, less memory
                parse_options=pc.ParseOptions(newlines_in_values=b'"' in self._data),
                convert_options=pc.ConvertOptions(
                    include_columns=list(want),
                    column_types={name: pa.string() if kind == CELLS else pa.float64()
                                  for name, kind in want.items()},
                    null_values=[], strings_can_be_null=False))
        except (pa.ArrowInvalid, pa.ArrowKeyError):
            return None  # a ragged row, a cell that is no number (or a blank one), ...
        numbers, cells = {}, {}
        for name, kind in want.items():
            if kind == CELLS:  # one str per distinct cell (traces repeat their date-times)
                col = table.column(name).combine_chunks().dictionary_encode()
                words = col.dictionary.to_pylist()
                cells[name] = [words[i] for i in col.indices.to_numpy(zero_copy_only=False)]
                continue
            values = numbers_of(table.column(name))
            if not np.isfinite(values).all():
                return None
            numbers[name] = values
        return Columns(self.path, table.num_rows, numbers, cells, {})

    def _read_csv(self, want: dict[str, str]) -> Columns:
        # DictReader's rules: the last column of a repeated name; None past a short row's end
        where = {name: max(j for j, h in enumerate(self.names) if h == name) for name in want}
        parts: dict[str, list] = {name: [] for name in want}
        errors: dict[str, ScenarioError] = {}
        dedup: dict = {}
        n = 0
        chunk: list[list[str]] = []
        for row in self._rows:
            if not row:
                continue  # a blank line (csv.DictReader skips them too)
            chunk.append(row)
            if len(chunk) == CHUNK_ROWS:
                self._convert(chunk, n, want=want, where=where, parts=parts, errors=errors,
                              dedup=dedup)
                n += len(chunk)
                chunk = []
        if chunk:
            self._convert(chunk, n, want=want, where=where, parts=parts, errors=errors,
                          dedup=dedup)
            n += len(chunk)
        numbers = {name: np.concatenate(p) if p else np.empty(0) for name, p in parts.items()
                   if want[name] != CELLS}
        cells = {name: [v for p in parts[name] for v in p] for name in want
                 if want[name] == CELLS}
        return Columns(self.path, n, numbers, cells, errors)

    def _convert(self, chunk: list[list[str]], first: int, *, want: dict[str, str],
                 where: dict[str, int], parts: dict[str, list],
                 errors: dict[str, ScenarioError], dedup: dict) -> None:
        width = min(map(len, chunk))
        for name, kind in want.items():
            j = where[name]
            values = list(map(operator.itemgetter(j), chunk)) if j < width else \
                [r[j] if j < len(r) else None for r in chunk]
            if kind == CELLS:
                parts[name].append([dedup.setdefault(v, v) for v in values])
                continue
            try:  # the usual case: every cell a finite number
                got = np.fromiter(map(float, values), np.float64, len(values))
                fine = bool(np.isfinite(got).all())
            except (TypeError, ValueError):
                fine = False
            if not fine:
                got = self._slow(name, values, first, kind == NUMBER_OR_BLANK, errors)
            parts[name].append(got)

    def after_rows(self, error: ScenarioError) -> ScenarioError:
        """``error``, once the rest of the file is read (a file that does not parse says so
        before a header's error does)."""
        self.read({})
        return error


def numbers_of(col) -> np.ndarray:
    """A numeric Arrow column without nulls (a ``ChunkedArray``) as a numpy array, read from
    its buffers: pyarrow's ``to_numpy`` imports pandas (a fifth of a second and tens of MB
    inside a run that never uses it)."""
    dtype = np.dtype(col.type.to_pandas_dtype()) if col.type.num_fields == 0 else None
    if dtype is None or col.null_count or dtype.kind not in "iuf" \
            or dtype.itemsize * 8 != col.type.bit_width:
        return col.to_numpy()
    parts = [np.frombuffer(c.buffers()[1], dtype=dtype, count=len(c),
                           offset=c.offset * dtype.itemsize) for c in col.chunks]
    if len(parts) == 1:  # read-only, as pyarrow's zero-copy answer is
        return parts[0]
    return np.concatenate(parts) if parts else np.empty(0, dtype)
