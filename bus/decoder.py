"""zenoh-cli decoder plugin: ``zenoh subscribe -k 'sc/**' --decoder swarmcover``.

Registered in the entry-point group ``zenoh_cli.codecs.decoders``; a callable
``(key, bytes) -> str`` returning one JSON line.
"""
from __future__ import annotations

import json

from .messages import WireError
from .messages import decode as decode_message


def decode_json(key: str, payload: bytes) -> str:
    """One JSON object: the decoded message with _t/_v, or an _error naming the field."""
    try:
        d = decode_message(payload).to_dict()
    except WireError as e:
        d = {"_error": str(e), "_bytes": len(payload)}
    return json.dumps({"key": str(key), **d}, separators=(",", ":"))


def decode(key, payload) -> str:
    """The entry point: zenoh-cli calls it with the key and the payload bytes."""
    return decode_json(key, bytes(payload))
