"""Which corpus clips the defaults were chosen on (tuning) and which they are only checked on (validation).

The membership is data: a clip is a tuning clip when its bytes have the SHA-256 of one of `TUNING`
(the clips the default terms, weights and thresholds were chosen on; models/cmu/README.md lists the
same with a "Set" column); every other clip, whatever its name, is a validation clip. A tuning clip
renamed is still tuning; an edited copy is not. Never choose or tune a default on a validation clip
(docs/corpus.md "Tuning and validation").
"""
from __future__ import annotations

import hashlib
from pathlib import Path

TUNING_SET = "tuning"
VALIDATION_SET = "validation"
SETS = (TUNING_SET, VALIDATION_SET)

#: {SHA-256 of the file: CMU id} of the tuning clips (the files in models/cmu/)
TUNING = {
    "fe35fa5767a02eada3374567f4adf6e0acb509ef14118793641409c19c070a8f": "127_33",
    "f41afeed5253a494d6cc04be59c06239cbae82621af6526052c5bb8650edca5a": "16_23",
    "432052e9114663ca770a368f8984d1075c9106b6ecc9753f7a9e496b7ae42362": "35_17",
    # the keyframes' footplant (runner/capture/foot_plant.py) was designed on 83_02's float misses
    "19906172ff7b447bda304ef7f86450a206ccde5dd10ec10773401860cca32e80": "83_02",
    # the repair of tracking glitches (runner/capture/glitches.py) was added for 74_05's flipping ankle
    "f46d31f114070b74a08c39f8e464057bfa48675b05107fbc2c333cda13124532": "74_05",
}


def clip_set(path: str | Path, sha256: str | None = None) -> str:
    """"tuning" or "validation" for the clip at `path` (its SHA-256 computed unless given).

    Raises:
        OSError: the file cannot be read (when `sha256` is not given).
    """
    if sha256 is None:
        sha256 = hashlib.sha256(Path(path).read_bytes()).hexdigest()
    return TUNING_SET if sha256 in TUNING else VALIDATION_SET
