"""Reading the XML inputs users hand us (maps, stations): clear errors that name the file."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path


def read_xml_root(path: str | Path, what: str) -> ET.Element:
    """The root element of the XML file ``path``.

    Args:
        path: the file.
        what: what the file is, for the messages (e.g. ``"GraphML file"``).

    Raises:
        FileNotFoundError: ``path`` is not a file.
        ValueError: ``path`` is not well-formed XML.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{what} not found: {path}")
    try:
        return ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ValueError(f"{what} {path}: malformed XML ({exc})") from exc
