"""Decodes the first Unreal Live Link Face packet (version 6) that arrives on
127.0.0.1:PORT, written from the documented layout alone (docs/outputs.md), and prints
every field as one JSON line. Floats are printed with repr, so they read back exactly.

Layout, big-endian: u8 version | i32 n, n bytes device id | i32 n, n bytes subject name |
i32 frame number | f32 subframe | i32 fps numerator | i32 fps denominator | u8 count |
count x f32.

Usage: python3 livelink_decode.py PORT   (prints "listening" once bound)
"""
import json
import socket
import struct
import sys


def decode(packet):
    at = 0

    def take(fmt):
        nonlocal at
        size = struct.calcsize(fmt)
        if at + size > len(packet):
            raise ValueError(f"packet ends at {len(packet)} bytes, {fmt} needs {size} more at {at}")
        values = struct.unpack_from(fmt, packet, at)
        at += size
        return values if len(values) > 1 else values[0]

    def text():
        length = take(">i")
        if length < 0 or at + length > len(packet):
            raise ValueError(f"string of {length} bytes at {at - 4}")
        return take(f">{length}s").decode("utf-8")

    out = {"version": take(">B"), "device_id": text(), "subject": text(), "frame_number": take(">i"),
           "subframe": take(">f"), "fps_numerator": take(">i"), "fps_denominator": take(">i")}
    out["count"] = take(">B")
    out["values"] = list(take(f">{out['count']}f")) if out["count"] > 1 else [take(">f")]
    out["size"] = len(packet)
    out["left_over"] = len(packet) - at
    return out


def main():
    port = int(sys.argv[1])
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", port))
    receiver.settimeout(20)
    print("listening", flush=True)
    packet, _ = receiver.recvfrom(65536)
    print(json.dumps(decode(packet)), flush=True)


if __name__ == "__main__":
    main()
