"""The OSL sources as the tests read them: a file of osl/, and the value of a #define in a text
(the twins' constants are held equal to the numpy ones through it)."""
import re
from pathlib import Path

OSL_DIR = Path(__file__).resolve().parent.parent / "osl"


def source(name: str) -> str:
    """The text of osl/<name> (a shader or a header)."""
    return (OSL_DIR / name).read_text()


def define(text: str, name: str) -> str:
    """The value of `#define NAME value` in text; a missing macro fails, naming it."""
    match = re.search(rf"^\s*#define {re.escape(name)}\s+(\S+)", text, re.M)
    assert match, f"no #define {name}"
    return match.group(1)


def define_float(text: str, name: str) -> float:
    return float(define(text, name))
