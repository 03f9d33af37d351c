"""The lowest layer: what every other layer may use, and which knows nothing of them.

- :mod:`evcd.utils.validation`: checking a setting, with one kind of message;
- :mod:`evcd.utils.atomic`: atomic file writes (text, JSON, PNG);
- :mod:`evcd.utils.checkpoint`: checkpoint files (atomic, checksummed, read without unpickling; torch);
- :mod:`evcd.utils.xml_files`: reading the XML inputs users hand us;
- :mod:`evcd.utils.sumo_tools`: the SUMO command-line tools of the ``eclipse-sumo`` wheel.

Nothing is imported here, so that a module needing one of them does not pay for the others (torch).
"""
