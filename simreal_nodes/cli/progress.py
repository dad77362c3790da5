"""Progress bars for the long-running commands (model builds, bag rendering)."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from tqdm import tqdm


class TqdmProgress:
    """progress(stage, done, total, message) -> one tqdm bar per stage."""

    def __init__(self) -> None:
        from tqdm import tqdm

        self._tqdm = tqdm
        self._bars: dict[str, tqdm[Any]] = {}

    def __call__(self, stage: str, done: int, total: int, message: str = "") -> None:
        bar = self._bars.get(stage)
        if bar is None:
            bar = self._tqdm(total=total, desc=f"{stage:>18}", unit="", leave=True, file=sys.stderr, dynamic_ncols=True)
            self._bars[stage] = bar
        bar.n = done
        bar.set_postfix_str(message[:60], refresh=False)
        bar.refresh()

    def close(self) -> None:
        for b in self._bars.values():
            b.close()
