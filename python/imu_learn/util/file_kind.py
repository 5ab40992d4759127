"""What a file given to the wrong option more likely is, and which option takes it: the one rule the
profile reader (``--profile``) and the checkpoint loader (``--checkpoint``) name a mix-up by."""
from __future__ import annotations

from pathlib import Path

# by suffix: (what it likely is, what takes it); "profile" and "checkpoint" are the options' own kinds
_SUFFIXES = {
    (".pt", ".pth", ".ckpt"): ("checkpoint", "a checkpoint? give it with --checkpoint"),
    (".onnx", ".ts"): ("export", "an exported model (imu-learn export)? imu-learn applies the checkpoint it came from "
                                 "(--checkpoint)"),
    (".yaml", ".yml"): ("kalibr", "imu.yaml is the noise in Kalibr's form; give the profile.json beside it"),
}


def mix_up(path: Path, wanted: str) -> str:
    """``": <what path likely is and what takes it>"`` for a file given where a ``wanted`` one
    ("profile" or "checkpoint") was expected, or ``""`` when nothing is known: a folder, a JSON file
    (a profile) given as a checkpoint, a checkpoint, an export or Kalibr's imu.yaml by their suffixes."""
    path = Path(path)
    if path.is_dir():
        return ": a folder; give its best.pt or last.pt" if wanted == "checkpoint" else ""
    if wanted != "profile" and _starts_with_brace(path):
        return (": a JSON file (a device profile? refine and navigate apply it with --profile; export takes a "
                "checkpoint only)")
    for suffixes, (kind, words) in _SUFFIXES.items():
        if path.suffix.lower() in suffixes and kind != wanted:
            return f": {words}"
    return ""


def _starts_with_brace(path: Path) -> bool:
    try:
        with open(path, "rb") as f:
            return f.read(64).lstrip().startswith(b"{")
    except OSError:
        return False
