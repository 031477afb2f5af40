"""Model and checkpoint files with integrity checks: nothing corrupt loads silently.

Two kinds of file, both written atomically (temporary file, fsync, rename):

- **Model files** (``model.pt``) are plain ``torch.save`` files, so ``torch.load`` still reads them.
  Their SHA-256 lives in the model card beside them (``model.json``, fields ``file``, ``bytes`` and
  ``sha256``); :func:`read_model_file` refuses a model whose card is missing or whose bytes differ.
- **Checkpoints** (``checkpoint.pt``) carry their checksum inside: one header line
  ``GTT-CHECKPOINT sha256=<hex> bytes=<n>`` followed by the ``torch.save`` bytes. A checkpoint is
  rewritten every few hundred steps; a checksum in a second file could disagree with it after a kill
  between the two renames, and the run could then not resume.

Every failure is one :class:`~gttnet.errors.ModelError` line naming the file, what was expected and
what was found (an empty, truncated, bit-flipped or foreign file), never an unpickling traceback.

**Files are data, never code.** Both kinds are read with ``torch.load(weights_only=True)``: only
tensors, numbers, strings, lists, tuples and dicts come back, and a file that would need any other
Python object (a pickled function call) is refused with one line naming the file and that object,
before anything runs. The checksum proves a file is intact, not who wrote it. The one allowance is
numpy's array reconstruction (plain arrays, no object is called) for checkpoints written before the
NumPy generator state was stored as a tensor.

Example::

    save_model("runs/a/model.pt", net, card={"steps": 100})  # writes model.pt and model.json
    net = load_model("runs/a/model.pt")                     # checks model.json's sha256 first
"""

from __future__ import annotations

import hashlib
import io
import json
import logging
import pickle
import re
import warnings
from dataclasses import asdict, is_dataclass
from pathlib import Path

import torch

from gttdata.fileio import atomic_write, file_sha256
from gttnet.errors import ModelError

__all__ = [
    "CHECKPOINT_FORMAT",
    "MODEL_FORMAT",
    "card_path",
    "load_checked",
    "read_model_file",
    "save_checked",
    "write_model_file",
]

log = logging.getLogger(__name__)

MODEL_FORMAT = "gttnet-model/1"
CHECKPOINT_FORMAT = "gttnet-checkpoint/3"  # 3: plain NumPy generator state
_MAGIC = b"GTT-CHECKPOINT"
_HEADER_RE = re.compile(rb"^GTT-CHECKPOINT sha256=([0-9a-f]{64}) bytes=(\d+)\n")


def _torch_bytes(payload: object) -> bytes:
    buf = io.BytesIO()
    torch.save(payload, buf)
    return buf.getvalue()


_UNSAFE_RE = re.compile(r"Unsupported global: GLOBAL ([\w.<>]+)")


def _legacy_numpy_globals() -> list:
    """What numpy arrays of plain dtype need under ``weights_only`` (checkpoints before format 3).

    ``_reconstruct`` only builds an empty ``ndarray`` whose bytes ``__setstate__`` then fills; no other
    callable becomes reachable, so the allow-list stays weights-only.
    """
    import numpy as np

    multiarray = getattr(np, "_core", None) or np.core  # numpy 2 / numpy 1
    return [
        multiarray.multiarray._reconstruct,
        np.ndarray,
        np.dtype,
        *(type(np.dtype(t)) for t in ("u4", "i8", "f8")),
    ]


def _unpickle(data: bytes, path: Path, what: str, *, legacy_numpy: bool = False) -> object:
    """``torch.load`` of ``data`` with ``weights_only=True``: tensors and plain containers, never code.

    Raises:
        ModelError: One line: a file that needs any other global (code) or that torch cannot read.
    """
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # torch's notes about pickle protocols
            if legacy_numpy:
                with torch.serialization.safe_globals(_legacy_numpy_globals()):
                    return torch.load(io.BytesIO(data), map_location="cpu", weights_only=True)
            return torch.load(io.BytesIO(data), map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types (EOFError, UnpicklingError, RuntimeError...)
        unsafe = _UNSAFE_RE.search(str(exc)) if isinstance(exc, pickle.UnpicklingError) else None
        if unsafe is not None or (isinstance(exc, pickle.UnpicklingError) and "Unsupported" in str(exc)):
            found = f"a pickled call to {unsafe.group(1)}" if unsafe else "pickled objects"
            raise ModelError(
                f"{path}: expected a {what} holding weights only (tensors, numbers, strings, lists, dicts), "
                f"found {found}; refused without running it (files are data, never code)"
            ) from None
        raise ModelError(
            f"{path}: expected a {what} (torch file), found {len(data)} bytes it cannot read "
            f"({exc.__class__.__name__})"
        ) from exc


def _read(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise ModelError(f"{path}: cannot read ({exc.strerror or exc})") from exc


# -- checkpoints (checksum inside) --------------------------------------------------------------------


def save_checked(path: str | Path, payload: dict) -> Path:
    """Write ``payload`` (a ``torch.save``-able dict) with a SHA-256 header, atomically.

    Raises:
        OutputError: One line naming the path when the write fails (full disk, read-only...).
    """
    path = Path(path)
    data = _torch_bytes(payload)
    header = f"{_MAGIC.decode()} sha256={hashlib.sha256(data).hexdigest()} bytes={len(data)}\n".encode()
    with atomic_write(path, "wb") as fh:
        fh.write(header)
        fh.write(data)
    return path


def load_checked(path: str | Path, *, what: str = "checkpoint") -> dict:
    """Read a file written by :func:`save_checked`, refusing it unless its SHA-256 matches.

    A file without the header (a checkpoint written before checksums existed) is read unverified, with
    a warning.

    Raises:
        ModelError: Missing, empty, truncated, bit-flipped or unreadable file (one line).
    """
    path = Path(path)
    if not path.is_file():
        raise ModelError(f"{path}: no {what} file there")
    raw = _read(path)
    if not raw:
        raise ModelError(f"{path}: expected a {what}, found an empty file (0 bytes)")
    if not raw.startswith(_MAGIC):
        old = _unpickle(raw, path, what, legacy_numpy=True)
        if not isinstance(old, dict):
            raise ModelError(f"{path}: expected a {what} (a mapping), found {type(old).__name__}")
        log.warning("%s: %s has no checksum (written by an older gttnet); loaded unverified", path, what)
        return old
    m = _HEADER_RE.match(raw[:200])
    if m is None:
        raise ModelError(
            f"{path}: expected a '{_MAGIC.decode()} sha256=... bytes=...' header, found a damaged one"
        )
    data = raw[m.end() :]
    expected_n = int(m.group(2))
    if len(data) != expected_n:
        raise ModelError(
            f"{path}: expected {expected_n} bytes after the header, found {len(data)} (truncated or extended)"
        )
    digest = hashlib.sha256(data).hexdigest()
    if digest != m.group(1).decode():
        raise ModelError(
            f"{path}: sha256: expected {m.group(1).decode()[:16]}..., found {digest[:16]}... (the file is corrupt)"
        )
    payload = _unpickle(data, path, what, legacy_numpy=True)
    if not isinstance(payload, dict):
        raise ModelError(f"{path}: expected a {what} (a mapping), found {type(payload).__name__}")
    return payload


# -- model files (checksum in the card) -----------------------------------------------------------------


def card_path(model_path: str | Path) -> Path:
    """The model card of a model file: same name, ``.json`` suffix."""
    return Path(model_path).with_suffix(".json")


def model_config_dict(model: torch.nn.Module) -> dict:
    """``model.config`` (a dataclass instance) as a plain dict, for model and checkpoint files."""
    cfg = getattr(model, "config", None)
    if cfg is None or not is_dataclass(cfg) or isinstance(cfg, type):
        raise ModelError(
            f"{type(model).__name__}.config must be a dataclass instance, got {type(cfg).__name__}"
        )
    return asdict(cfg)


def write_model_file(path: str | Path, model: torch.nn.Module, *, card: dict | None = None) -> Path:
    """Write a model file (float32 CPU weights + config) and its card with the file's SHA-256.

    Args:
        path: Destination ``.pt`` file (its folder is created).
        model: The network; ``model.config`` must be a dataclass.
        card: Extra card fields (recipe, data, metrics...), JSON-serialisable.

    Returns:
        The model path.

    Raises:
        OutputError: One line naming the path when a write fails.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        from gttdata.fileio import write_error

        raise write_error(path.parent, exc) from exc
    state = {k: v.detach().cpu().float() for k, v in model.state_dict().items()}
    config = model_config_dict(model)
    data = _torch_bytes({"format": MODEL_FORMAT, "config": config, "state_dict": state})
    with atomic_write(path, "wb") as fh:
        fh.write(data)
    info = {
        "format": MODEL_FORMAT,
        "file": path.name,
        "bytes": len(data),
        "sha256": hashlib.sha256(data).hexdigest(),
        "config": config,
        **{k: v for k, v in (card or {}).items() if k not in ("format", "file", "bytes", "sha256", "config")},
    }
    with atomic_write(card_path(path), "w") as fh:
        fh.write(json.dumps(info, indent=2, default=str) + "\n")
    return path


def _check_card(path: Path) -> None:
    """Refuse ``path`` unless its card exists and its size and SHA-256 match the card."""
    cpath = card_path(path)
    if not cpath.is_file():
        raise ModelError(
            f"{path}: expected its model card {cpath.name} beside it (it holds the file's sha256), found none; "
            "copy the card with the model, or re-save it with gttnet.model.inference.save_model"
        )
    try:
        card = json.loads(cpath.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ModelError(f"{cpath}: expected a JSON model card, found unreadable text ({exc})") from exc
    sha = card.get("sha256") if isinstance(card, dict) else None
    if not isinstance(sha, str) or len(sha) != 64:
        raise ModelError(
            f"{cpath}: field sha256: expected the model file's 64-hex-digit SHA-256, found {sha!r}"
        )
    size = path.stat().st_size
    if size == 0:
        raise ModelError(f"{path}: expected a model of {card.get('bytes', '?')} bytes, found an empty file")
    if card.get("bytes") is not None and int(card["bytes"]) != size:
        raise ModelError(
            f"{path}: size: expected {card['bytes']} bytes (model card), found {size} (truncated?)"
        )
    digest = file_sha256(path)
    if digest != sha:
        raise ModelError(
            f"{path}: sha256: expected {sha[:16]}... (model card {cpath.name}), found {digest[:16]}... "
            "(the file is corrupt or is not the model the card describes)"
        )


def read_model_file(path: str | Path) -> dict:
    """The verified payload of a model file or a checkpoint: ``{"config": dict, "state_dict": dict}``.

    A model file (``model.pt``) is checked against its card; a checkpoint against its header.

    Raises:
        ModelError: Missing file or card, checksum mismatch, unreadable or foreign file (one line).
    """
    path = Path(path)
    if not path.is_file():
        raise ModelError(f"no trained model is available: {path} does not exist")
    with open(path, "rb") as fh:
        head = fh.read(len(_MAGIC))
    if head == _MAGIC or (path.name == "checkpoint.pt" and not card_path(path).is_file()):
        payload = load_checked(path)
        cfg, state = payload.get("model_config"), payload.get("model")
    else:
        _check_card(path)
        loaded = _unpickle(_read(path), path, "GTT-Net model")
        if not isinstance(loaded, dict):
            raise ModelError(f"{path}: expected a GTT-Net model (a mapping), found {type(loaded).__name__}")
        payload = loaded
        cfg, state = (
            payload.get("config", payload.get("model_config")),
            payload.get("state_dict", payload.get("model")),
        )
    if not isinstance(cfg, dict) or not isinstance(state, dict):
        raise ModelError(
            f"{path}: expected a GTT-Net model with 'config' and 'state_dict', found keys {sorted(payload)}"
        )
    return {"config": cfg, "state_dict": state}
