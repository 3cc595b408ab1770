#!/usr/bin/env python3
"""Independent check of a linetrack MCAP recording with the PyPI `mcap` reader.

Usage: check_mcap.py FILE.mcap

Reads the file with mcap's own reader (not linetrack's code), decodes every message
(protobuf channels with mcap-protobuf-support's decoder, built from the schema the file
carries; JSON channels with the json module), and prints one JSON object on stdout:

  {"summary": true|false,           # the file was closed: it has its summary section
   "channels": {topic: {"schema": name, "encoding": enc, "count": n}},
   "sequences": {topic: [sequence numbers]},   # image channels only: the frame ids
   "metadata": {name: {...}},
   "errors": ["..."]}                # messages that did not decode, and why

Exit status 0 when the file was read to its end, 1 otherwise (the reason on stderr).
"""

import json
import sys

from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory


def main() -> int:
    if len(sys.argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    path = sys.argv[1]
    result = {"summary": False, "channels": {}, "sequences": {}, "metadata": {}, "errors": []}
    try:
        with open(path, "rb") as stream:
            reader = make_reader(stream, decoder_factories=[DecoderFactory()])
            summary = reader.get_summary()
            result["summary"] = summary is not None
            for schema, channel, message in reader.iter_messages():
                topic = channel.topic
                entry = result["channels"].setdefault(
                    topic,
                    {
                        "schema": schema.name if schema else None,
                        "encoding": channel.message_encoding,
                        "count": 0,
                    },
                )
                entry["count"] += 1
                try:
                    if channel.message_encoding == "json":
                        json.loads(message.data)
                    else:
                        decoded = reader_decode(reader, schema, channel, message)
                        if topic.endswith("/image"):
                            size = decoded.width * decoded.height
                            if len(decoded.data) != size or decoded.encoding != "mono8":
                                raise ValueError(
                                    f"{decoded.width}x{decoded.height} {decoded.encoding} with {len(decoded.data)} bytes"
                                )
                except Exception as error:  # every failure is reported, none stops the check
                    result["errors"].append(f"{topic} #{message.sequence}: {error}")
                if topic.endswith("/image"):
                    result["sequences"].setdefault(topic, []).append(message.sequence)
            for record in reader.iter_metadata():
                result["metadata"][record.name] = dict(record.metadata)
    except Exception as error:
        print(f"{path}: {error}", file=sys.stderr)
        print(json.dumps(result))
        return 1
    print(json.dumps(result))
    return 0


_decoders = {}


def reader_decode(reader, schema, channel, message):
    """Decodes a protobuf message with a decoder made from the file's own schema."""
    key = schema.id
    if key not in _decoders:
        decoder = DecoderFactory().decoder_for(channel.message_encoding, schema)
        if decoder is None:
            raise ValueError(f"no decoder for {channel.message_encoding} / {schema.name}")
        _decoders[key] = decoder
    return _decoders[key](message.data)


if __name__ == "__main__":
    sys.exit(main())
