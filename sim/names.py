"""Name prefixes of the scene's parts (MjSpec.attach prefixes): one place for all of them."""

ARM = "arm/"
STEWART = "stewart/"
PLATE = "plate/"
TRAY = "tray/"


def conductor(k: int) -> str:
    """Prefix of conductor k (0-based)."""
    return f"conductor{k}/"


def conductor_body(k: int) -> str:
    """Body name of conductor k."""
    return f"{conductor(k)}conductor"
