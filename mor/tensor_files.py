"""Model files as plain values: the one way MOR writes and reads torch files (L-Net and policy checkpoints).

``save_plain`` writes a dict of tensors and plain Python values through a temporary name; its bytes depend on the
content only (not on the temporary name, which torch would otherwise write into the archive), so the same weights
make the same file and the same digest. ``load_plain`` reads it with ``torch.load(weights_only=True)``: a crafted
file that would run code when unpickled is refused (``UnsafeFile``) and nothing in it runs.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import torch

from mor.atomic import atomic_output
from mor.errors import MorError


class UnsafeFile(MorError):
    """A file that would need unpickling (running code) to load: a pickle of objects, old or crafted."""


def save_plain(payload: dict[str, Any], path: Path) -> None:
    """``payload`` (tensors and plain values) to ``path``, whole or not at all."""
    buffer = io.BytesIO()
    torch.save(payload, buffer)
    with atomic_output(path) as partial:
        partial.write_bytes(buffer.getvalue())


def load_plain(path: Path, kind: str, unsafe_hint: str, damaged_hint: str, device: torch.device | str = "cpu"
               ) -> Any:
    """What ``save_plain`` wrote to ``path``, on ``device``, without unpickling anything. kind: what the file should be
    (e.g. "policy file"); the hints say what to do about an unsafe or a damaged file. Raises ``UnsafeFile`` or a
    one-line MorError naming ``path``."""
    try:
        return torch.load(path, map_location=device, weights_only=True)
    except Exception as error:  # noqa: BLE001 - torch raises many kinds for a damaged or unsafe file
        if "weights_only" in str(error):
            raise UnsafeFile(f"{path}: refused, loading it would run code (it pickles more than tensors and plain "
                             f"values); {unsafe_hint}") from None
        raise MorError(f"{path}: not a readable {kind} ({type(error).__name__}: cut short or damaged); "
                       f"{damaged_hint}") from None
