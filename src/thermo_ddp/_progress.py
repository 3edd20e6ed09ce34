"""Progress bars (tqdm) of long steps: shown on a terminal, hidden when asked or when stderr is a file."""
from __future__ import annotations


def hidden(progress: bool | None) -> bool | None:
    """tqdm's ``disable`` for ``progress``: True (show), False (hide), None (show only on a terminal)."""
    return None if progress is None else not progress
