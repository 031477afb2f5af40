"""Read a pandas DataFrame stored in HDF5 (``DataFrame.to_hdf``) with h5py alone, never running its pickles.

``pandas.read_hdf`` unpickles whatever the file holds (object columns, and through PyTables every
pickled attribute), so a keypoint file could run code. This reader understands the two layouts pandas
writes and takes only numbers and strings from them:

- **fixed** (``format="fixed"``, group attribute ``pandas_type = "frame"``): the column index in
  ``axis0`` (or, for a MultiIndex, the unique values ``axis0_level<i>`` and the codes
  ``axis0_label<i>``), the row index in ``axis1``, and the values in ``block<i>_values`` with their
  column labels in ``block<i>_items``. An object block (a pickled ``VLArray``) is refused.
- **table** (``format="table"``, ``pandas_type = "frame_table"``): one compound dataset ``table``
  with an ``index`` field and ``values_block_<i>`` fields; the column labels and level names are
  small pickles of lists, tuples and strings in the attributes. They are decoded by an unpickler that
  resolves no global at all (the "restricting globals" pattern of Python's pickle documentation):
  only str, bytes, int, float, bool, None, list, tuple, dict and set can come out, so nothing can be
  called. Anything else is refused.

Every refusal is one :class:`~gttdata.errors.KeypointFormatError` line naming the file and what was
found.
"""

from __future__ import annotations

import io
import pickle
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gttdata.errors import KeypointFormatError

__all__ = ["PandasFrame", "plain_unpickle", "read_pandas_frame"]

_MAX_ATTR_PICKLE = 16 << 20  # column labels of even a huge project are far below this


@dataclass(frozen=True)
class PandasFrame:
    """A numeric DataFrame read from HDF5.

    Args:
        columns: Column labels, one tuple per column (one element per column level).
        names: Column level names (``None`` where unnamed).
        values: The values, shape ``(n_rows, n_columns)`` float64.
        index: Row labels as strings, length ``n_rows``.
    """

    columns: list[tuple]
    names: list[str | None]
    values: np.ndarray
    index: list[str]


class _NoGlobals(pickle.Unpickler):
    """An unpickler that resolves no global: only builtin data (str, int, list, tuple, dict...) loads."""

    def find_class(self, module: str, name: str):  # noqa: D102 - pickle's hook
        raise pickle.UnpicklingError(f"global {module}.{name}")

    def persistent_load(self, pid):  # noqa: D102 - pickle's hook
        raise pickle.UnpicklingError("persistent id")


def plain_unpickle(data: bytes, *, where: str) -> object:
    """Decode a pickle of builtin data only (lists, tuples, dicts, strings, numbers); never call anything.

    Example:
        >>> plain_unpickle(pickle.dumps([("a", 1)], protocol=0), where="x")
        [('a', 1)]

    Raises:
        KeypointFormatError: The pickle names any global (a class or function), or is damaged.
    """
    if len(data) > _MAX_ATTR_PICKLE:
        raise KeypointFormatError(f"{where}: expected a small pickled list, found {len(data)} bytes")
    try:
        return _NoGlobals(io.BytesIO(data), encoding="utf-8").load()
    except pickle.UnpicklingError as exc:
        raise KeypointFormatError(
            f"{where}: expected plain data (lists, strings, numbers), found a pickled {exc}; "
            "refused without running it (files are data, never code)"
        ) from None
    except Exception as exc:  # noqa: BLE001 - damaged pickles raise many types
        raise KeypointFormatError(
            f"{where}: unreadable pickled attribute ({exc.__class__.__name__})"
        ) from None


def _attr(obj, name: str, default=None):
    v = obj.attrs.get(name, default)
    if isinstance(v, np.bytes_ | bytes):
        return bytes(v)
    if isinstance(v, np.generic):
        return v.item()
    return v


def _text(v) -> str:
    return v.decode("utf-8") if isinstance(v, bytes) else str(v)


def _numeric(ds, where: str) -> np.ndarray:
    import h5py

    if not isinstance(ds, h5py.Dataset):
        raise KeypointFormatError(f"{where}: expected an HDF5 dataset, found {type(ds).__name__}")
    if ds.dtype.kind not in "fiub" or h5py.check_vlen_dtype(ds.dtype) is not None:
        raise KeypointFormatError(
            f"{where}: expected numbers, found {_kind_name(ds)}; refused without unpickling (files are data, never code)"
        )
    return ds[()]


def _kind_name(ds) -> str:
    pseudo = _attr(ds, "PSEUDOATOM")
    if pseudo is not None:
        return f"pickled {_text(pseudo)} values"
    return f"dtype {ds.dtype}"


def _labels(ds, where: str, encoding: str) -> list:
    """Values of an index dataset (``kind`` string, integer, float): strings or numbers."""
    import h5py

    if not isinstance(ds, h5py.Dataset):
        raise KeypointFormatError(f"{where}: expected an HDF5 dataset, found {type(ds).__name__}")
    kind = _text(_attr(ds, "kind", b""))
    if ds.dtype.kind == "S":
        return [bytes(v).decode(encoding) for v in ds[()]]
    if ds.dtype.kind in "iuf" and kind in ("", "integer", "float"):
        return ds[()].tolist()
    raise KeypointFormatError(
        f"{where}: expected string or number labels, found {kind or _kind_name(ds)} labels "
        "(object labels are pickles; refused)"
    )


def _index(group, key: str, where: str, encoding: str) -> tuple[list[tuple], list[str | None]]:
    """Labels (one tuple each) and level names of a fixed-format index stored under ``key``."""
    variety = _text(_attr(group, f"{key}_variety", b"regular"))
    if variety == "regular":
        if key not in group:
            raise KeypointFormatError(f"{where}: dataset {key!r} is missing")
        ds = group[key]
        name = _attr(ds, "name")
        name = None if name is None or _text(name) == "N." else _text(name)
        return [(v,) for v in _labels(ds, f"{where}/{key}", encoding)], [name]
    if variety != "multi":
        raise KeypointFormatError(f"{where}: {key}_variety: expected 'regular' or 'multi', found {variety!r}")
    nlevels = int(_attr(group, f"{key}_nlevels", 0))
    levels, codes, names = [], [], []
    for i in range(nlevels):
        lname, cname = f"{key}_level{i}", f"{key}_label{i}"
        if lname not in group or cname not in group:
            raise KeypointFormatError(
                f"{where}: datasets {lname!r} and {cname!r} are expected, one is missing"
            )
        levels.append(_labels(group[lname], f"{where}/{lname}", encoding))
        codes.append(_numeric(group[cname], f"{where}/{cname}").astype(np.int64))
        n = _attr(group[lname], "name")
        names.append(None if n is None or _text(n) == "N." else _text(n))
    if not codes or len({len(c) for c in codes}) != 1:
        raise KeypointFormatError(
            f"{where}: {key}: expected levels of equal length, found {len(codes)} levels"
        )
    labels = []
    for row in zip(*codes, strict=True):
        labels.append(tuple(levels[i][c] if 0 <= c < len(levels[i]) else None for i, c in enumerate(row)))
    return labels, names


def _read_fixed(group, where: str, encoding: str) -> PandasFrame:
    columns, names = _index(group, "axis0", where, encoding)
    rows, _ = _index(group, "axis1", where, encoding)
    by_label: dict[tuple, np.ndarray] = {}
    for b in range(int(_attr(group, "nblocks", 0))):
        vname = f"block{b}_values"
        if vname not in group:
            raise KeypointFormatError(f"{where}: dataset {vname!r} is missing")
        values = np.asarray(_numeric(group[vname], f"{where}/{vname}"), dtype=np.float64)
        if values.ndim != 2:
            raise KeypointFormatError(f"{where}/{vname}: expected 2 dimensions, found {values.ndim}")
        if not _attr(group[vname], "transposed", 0):
            values = values.T  # stored (items, rows)
        items, _ = _index(group, f"block{b}_items", where, encoding)
        if values.shape != (len(rows), len(items)):
            raise KeypointFormatError(
                f"{where}/{vname}: expected shape ({len(rows)}, {len(items)}), found {values.shape}"
            )
        for j, label in enumerate(items):
            by_label[label] = values[:, j]
    missing = [c for c in columns if c not in by_label]
    if missing:
        raise KeypointFormatError(f"{where}: column {missing[0]} has no values in any block")
    values = np.stack([by_label[c] for c in columns], axis=1) if columns else np.zeros((len(rows), 0))
    return PandasFrame(columns, names, values, [str(r[0]) if len(r) == 1 else str(r) for r in rows])


def _table_index(table, where: str, encoding: str) -> list[str]:
    if "index" not in table.dtype.names:
        raise KeypointFormatError(f"{where}/table: field 'index' is missing")
    raw = table.fields("index")[()]
    if raw.dtype.kind == "S":
        return [bytes(v).decode(encoding) for v in raw]
    if raw.dtype.kind in "iuf":
        return [str(v) for v in raw.tolist()]
    raise KeypointFormatError(f"{where}/table: index: expected numbers or strings, found {raw.dtype}")


def _read_table(group, where: str, encoding: str) -> PandasFrame:
    import h5py

    table = group.get("table")
    if not isinstance(table, h5py.Dataset) or table.dtype.names is None:
        raise KeypointFormatError(f"{where}: expected a compound dataset 'table' (pandas format='table')")
    ttype = _text(_attr(group, "table_type", b""))
    if ttype != "appendable_frame":
        raise KeypointFormatError(f"{where}: table_type: expected 'appendable_frame', found {ttype!r}")

    def pickled(obj, name: str) -> object:
        raw = _attr(obj, name)
        if not isinstance(raw, bytes):
            raise KeypointFormatError(f"{where}: attribute {name!r} is missing")
        return plain_unpickle(raw, where=f"{where}: attribute {name}")

    axes = pickled(group, "non_index_axes")
    cols = axes[0][1] if isinstance(axes, list) and axes and isinstance(axes[0], tuple) else None
    if not isinstance(cols, list):
        raise KeypointFormatError(
            f"{where}: non_index_axes: expected [(1, [column labels])], found {axes!r:.80}"
        )
    columns = [c if isinstance(c, tuple) else (c,) for c in cols]
    info = pickled(group, "info")
    names = info.get(1, {}).get("names") if isinstance(info, dict) and isinstance(info.get(1), dict) else None
    names = list(names) if isinstance(names, list | tuple) else [None] * (len(columns[0]) if columns else 1)
    blocks = pickled(group, "values_cols")
    if not isinstance(blocks, list):
        raise KeypointFormatError(f"{where}: values_cols: expected a list of names, found {blocks!r:.80}")
    by_label: dict[tuple, np.ndarray] = {}
    for b in blocks:
        if not isinstance(b, str) or b not in table.dtype.names:
            raise KeypointFormatError(f"{where}: values_cols names {b!r}, which the table does not hold")
        sub = table.dtype.fields[b][0]
        if sub.base.kind not in "fiub":
            raise KeypointFormatError(f"{where}/table: field {b!r}: expected numbers, found dtype {sub}")
        labels = pickled(table, f"{b}_kind")
        values = np.asarray(table.fields(b)[()], dtype=np.float64).reshape(table.shape[0], -1)
        if not isinstance(labels, list) or len(labels) != values.shape[1]:
            raise KeypointFormatError(f"{where}/table: {b}_kind: expected {values.shape[1]} column labels")
        for j, label in enumerate(labels):
            by_label[label if isinstance(label, tuple) else (label,)] = values[:, j]
    missing = [c for c in columns if c not in by_label]
    if missing:
        raise KeypointFormatError(f"{where}: column {missing[0]} has no values in the table")
    index = _table_index(table, where, encoding)
    values = np.stack([by_label[c] for c in columns], axis=1) if columns else np.zeros((len(index), 0))
    return PandasFrame(columns, names, values, index)


def read_pandas_frame(path: str | Path, key: str | None = None) -> PandasFrame:
    """Read the numeric DataFrame that ``DataFrame.to_hdf(path, key)`` wrote, without pandas or pickles.

    Args:
        path: The HDF5 file.
        key: The frame's group; default: the only top-level group pandas wrote (``pandas_type``).

    Returns:
        The frame's columns, level names, values (float64) and row labels.

    Raises:
        KeypointFormatError: Not HDF5, no pandas frame, several candidates, a layout other than
            fixed or table, object (pickled) columns, or an attribute that names any Python global.
    """
    import h5py

    path = Path(path)
    try:
        fh = h5py.File(path, "r")
    except OSError as exc:
        raise KeypointFormatError(
            f"{path}: expected an HDF5 file written by pandas, cannot open it ({exc})"
        ) from exc
    with fh:
        if key is None:
            found = [k for k, g in fh.items() if isinstance(g, h5py.Group) and "pandas_type" in g.attrs]
            if len(found) != 1:
                raise KeypointFormatError(
                    f"{path}: expected one pandas frame (a group with 'pandas_type'), found {found or 'none'}"
                )
            key = found[0]
        group = fh.get(key)
        if not isinstance(group, h5py.Group):
            raise KeypointFormatError(f"{path}: expected a pandas frame under {key!r}, found none")
        where = f"{path}:/{key}"
        kind = _text(_attr(group, "pandas_type", b""))
        encoding = _text(_attr(group, "encoding", b"UTF-8")) or "UTF-8"
        try:
            "".encode(encoding)
        except LookupError:
            raise KeypointFormatError(f"{where}: encoding: unknown text encoding {encoding!r}") from None
        if kind == "frame":
            return _read_fixed(group, where, encoding)
        if kind == "frame_table":
            return _read_table(group, where, encoding)
        raise KeypointFormatError(
            f"{where}: pandas_type: expected 'frame' (fixed) or 'frame_table' (table), found {kind!r}"
        )
