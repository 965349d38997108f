"""The one reader of torch checkpoint files (weights a method runs, training checkpoints, converted Keras
weights): ``torch.load(weights_only=True)`` on the CPU, after the file was checked to be a regular file
and to look like a torch checkpoint at all.

Whatever else a user hands in is named in one line, never with torch's own advice (its weights_only
paragraph suggests ``weights_only=False``, which would run arbitrary code from the file): ``a JSON
file, not a torch checkpoint``, ``an HDF5 file (a Keras checkpoint? ...)``, ``a training checkpoint
(resume state), not exported weights``, ``a subfocal checkpoint, not tinycnn``.

Exported weights hold ``{"format": WEIGHTS_FORMAT, "version", "method", "state_dict", "config",
"training"}``; ``method`` is the trainable network that wrote them (the method that runs them).
"""

from __future__ import annotations

import os
import pickle
import zipfile
from pathlib import Path
from typing import Any

from lfbench.utils.errors import DataError
from lfbench.utils.readfile import check_regular_file

#: ``format`` of exported weights (final.pt, best.pt, stage*.pt). The reader tells weights from a training
#: checkpoint by :data:`CHECKPOINT_FORMAT` only, so weights written under the format's earlier name
#: ("lfbench.subfocal.weights", e.g. the shipped methods/weights/subfocal_small.pt) read as they are.
WEIGHTS_FORMAT = "lfbench.weights"
#: ``format`` of a training checkpoint (the resume state of ``lfbench train``).
CHECKPOINT_FORMAT = "lfbench.train.checkpoint"

_HEAD = 512  # bytes read to tell what a file is
#: The largest checkpoint lfbench opens (weights and optimizer state of a network of ~700 million fp32
#: parameters); a larger file is refused from its size, before anything reads or hashes it.
MAX_CHECKPOINT_BYTES = 8 * 1024**3


def sniff(head: bytes) -> str | None:
    """What a file starting with ``head`` is when it cannot be a torch checkpoint (a phrase such as
    ``a JSON file``), or None when it may be one (a zip archive or a pickle)."""
    if head.startswith(b"PK\x03\x04") or head[:1] == b"\x80":
        return None  # torch's zip format, or its legacy pickle format
    if not head:
        return "an empty file"
    if head.startswith(b"\x89HDF\r\n\x1a\n"):
        return ("an HDF5 file (a Keras checkpoint? lfbench convert-keras turns SubFocal's, LFattNet's and EPINET's "
                "into weights)")
    if head.startswith(b"\x93NUMPY"):
        return "a NumPy array file"
    if head.startswith((b"\x89PNG", b"\xff\xd8\xff", b"GIF8", b"II*\x00", b"MM\x00*")):
        return "an image"
    if head.startswith((b"PF\n", b"Pf\n")):
        return "a PFM disparity map"
    stripped = head.lstrip()
    if stripped[:1] in (b"{", b"["):
        return "a JSON file"
    if b"\x00" not in head:
        try:
            head.decode("utf-8")
        except UnicodeDecodeError as exc:
            if exc.start < len(head) - 4:  # not merely a multi-byte character cut at the end of the head
                return "a binary file of another kind"
        return "a text file"
    return "a binary file of another kind"


def check_checkpoint_file(path: str | Path, what: str = "checkpoint file") -> None:
    """DataError naming ``path`` unless it may be a torch checkpoint, from bounded reads only (the first
    512 bytes and, for torch's zip format, the archive's directory at its end): a regular file of at most
    :data:`MAX_CHECKPOINT_BYTES`, of no other known kind (:func:`sniff`), and a zip archive that holds a
    pickle. Run before anything reads the whole file: loading it, or hashing it for a method's name (a
    sparse 50 GB file is refused here in microseconds)."""
    path = Path(path)
    check_regular_file(path, what)
    size = os.path.getsize(path)
    if size > MAX_CHECKPOINT_BYTES:
        raise DataError(f"{what} of {size / 1024**3:.1f} GiB, larger than the {MAX_CHECKPOINT_BYTES // 1024**3} GiB "
                        "lfbench reads", path)
    with open(path, "rb") as f:
        head = f.read(_HEAD)
    kind = sniff(head)
    if kind is not None:
        raise DataError(f"{kind}, not a torch checkpoint", path)
    if head.startswith(b"PK\x03\x04"):
        problem = _zip_problem(path)
        if problem is not None:
            raise DataError(f"{problem}, not a readable torch checkpoint", path)


def read_checkpoint(path: str | Path, what: str = "checkpoint file") -> dict[str, Any]:
    """The payload (a dict) of the torch checkpoint ``path``: ``torch.load(weights_only=True)`` on the
    CPU, after :func:`check_checkpoint_file`. DataError naming the file and, in one line, what it is
    instead: missing, not a regular file (a FIFO or device would block or never end), too large, another
    kind of file, damaged, or holding Python objects beyond tensors and plain values (refused, not
    unpickled)."""
    import torch

    path = Path(path)
    check_checkpoint_file(path, what)
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as exc:  # torch's weights-only refusal (its advice is not passed on)
        if "Unsupported global" not in str(exc):  # an opcode no pickle of plain values has: a damaged file
            raise DataError(f"{_damaged(path)}, not a readable torch checkpoint", path) from None
        raise DataError("holds Python objects beyond tensors and plain values; lfbench loads weights only and "
                        "does not unpickle it", path) from None
    except Exception:  # noqa: BLE001 - torch raises many kinds for a damaged file; what it is is enough
        raise DataError(f"{_damaged(path)}, not a readable torch checkpoint", path) from None
    if not isinstance(payload, dict):
        raise DataError(f"a torch file holding a {type(payload).__name__}, not an lfbench {what} (a dict)", path)
    return payload


def _zip_problem(path: Path) -> str | None:
    """What ``path`` is when it is not a zip archive holding torch's pickle (None when it is); reads the
    archive's directory only (at its end), never its members."""
    try:
        with zipfile.ZipFile(path) as z:
            names = z.namelist()
    except (zipfile.BadZipFile, OSError, ValueError):
        return "a damaged or incomplete file" if os.path.getsize(path) else "an empty file"
    if not any(n.endswith("data.pkl") for n in names):
        return "a zip archive"
    return None


def _damaged(path: Path) -> str:
    return _zip_problem(path) or "a damaged torch file"


def is_weights(payload: dict[str, Any]) -> bool:
    """Whether ``payload`` has the shape of exported weights (a state dict and the config to rebuild it)."""
    return isinstance(payload.get("state_dict"), dict) and isinstance(payload.get("config"), dict)


def read_weights(path: str | Path, network: str | None = None, same_network: tuple[str, ...] = ()
                 ) -> dict[str, Any]:
    """The payload of a weights file (``state_dict`` and ``config``) for the network ``network``: DataError
    naming the file when it is not weights (a training checkpoint: ``use OUT/final.pt``) or when it says
    it holds another network (``a subfocal checkpoint, not tinycnn``); ``same_network``: other names
    whose weights fit this network (SubFocal's and LFattNet's)."""
    payload = read_checkpoint(path, "weights file")
    if payload.get("format") == CHECKPOINT_FORMAT:
        raise DataError("a training checkpoint (the resume state of lfbench train), not exported weights: give "
                        "the run's final.pt, best.pt or stage*.pt", path)
    if not is_weights(payload):
        raise DataError("a torch checkpoint without 'state_dict' and 'config': not lfbench weights", path)
    stored = payload.get("method")
    if network is not None and isinstance(stored, str) and stored and stored not in (network, *same_network):
        if _is_name(stored):  # a name as the registries have them; any other text is not shown
            raise DataError(f"a {stored} checkpoint, not {network} (run it as {stored}:weights=...)", path)
        raise DataError(f"a checkpoint of another network, not {network}", path)
    return payload


def _is_name(text: str) -> bool:
    return 0 < len(text) <= 40 and all(c.isascii() and (c.isalnum() or c in "_-.") for c in text)


__all__ = ["check_checkpoint_file", "MAX_CHECKPOINT_BYTES", "read_checkpoint", "read_weights", "is_weights", "sniff",
           "WEIGHTS_FORMAT", "CHECKPOINT_FORMAT"]
