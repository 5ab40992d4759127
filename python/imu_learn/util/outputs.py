"""What a command may replace: only its own earlier outputs (:func:`check_replaceable`).

A command that writes to a path the user names (``imu-learn checkpoint strip``'s DST, ``imu-learn
export``'s and ``imu-learn evaluate``'s ``--out`` folder) replaces a file there only when an earlier
run of the same command wrote it; any other file (a user's CSV, notes, another tool's ``model.json``)
is refused before any work, with one line naming it and the fix, and is left as it was. Each command
says how it recognises its own output from what it writes anyway (a stripped checkpoint's
``extra.stripped_from``, an export's card, an evaluation's ``result.json``).
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Callable, Iterable, Optional

from imu_learn.errors import InvalidInputError

FIX = "remove it or give OUT a new name"


def check_replaceable(paths: Iterable[Path], not_own: Callable[[Path], Optional[str]], command: str,
                      fix: str = FIX) -> None:
    """Before any work: each of ``paths`` that exists (a file, a folder or a link) was written by an
    earlier run of ``command``, else the :class:`InvalidInputError` naming it, why it is not
    (``not_own(path)``: None for an earlier output, else the reason) and the ``fix``."""
    for path in paths:
        path = Path(path)
        if not os.path.lexists(path):
            continue
        why = "a folder" if path.is_dir() and not path.is_symlink() else not_own(path)
        if why is not None:
            raise InvalidInputError(f"{path} exists and is not an earlier {command} output ({why}): "
                                    f"{command} replaces only its own outputs; {fix}")
