#!/usr/bin/env python3
"""Rebuild the MCAP specification's conformance files for tests/io/mcap_conformance.

The MCAP repository (github.com/foxglove/mcap, MIT licence) keeps its conformance files
(tests/conformance/data/*/*.mcap) in Git LFS: a plain clone or snapshot holds only their LFS
pointers (the SHA-256 and size of each file), beside the expected records in JSON. This script
writes each file again from its inputs exactly as the repository's generator does
(tests/conformance/scripts/generate-inputs.ts with typescript/core's McapRecordBuilder and
ChunkBuilder), then proves each one byte for byte the official file: its SHA-256 and size must
equal the LFS pointer's. Files that do not match are reported and not written.

Output, in --out: BASE/NAME.mcap, BASE/expected.json (per file NAME, the expected records of the
data section up to and including Data End: what a streamed reader must hand over), SHA256SUMS (the official digests,
checked by `sha256sum -c` in the tests) and LICENSE (the MCAP repository's).

    python3 scripts/mcap_conformance.py --repo /path/to/mcap/git-dir --out tests/io/mcap_conformance

--repo is a git directory (bare, or a work tree's) holding foxglove/mcap; the files are read from
its HEAD with `git show`. Needs only the Python standard library.
"""
import argparse
import hashlib
import json
import pathlib
import struct
import subprocess
import sys
import zlib

MAGIC = b"\x89MCAP0\r\n"
OP = {"Header": 0x01, "Footer": 0x02, "Schema": 0x03, "Channel": 0x04, "Message": 0x05, "Chunk": 0x06,
      "MessageIndex": 0x07, "ChunkIndex": 0x08, "Attachment": 0x09, "AttachmentIndex": 0x0A,
      "Statistics": 0x0B, "Metadata": 0x0C, "MetadataIndex": 0x0D, "SummaryOffset": 0x0E, "DataEnd": 0x0F}
PAD = b"\x01\xff\xff"  # McapRecordBuilder's padRecords bytes
FEATURES = ("ch", "mx", "st", "rsh", "rch", "ax", "mdx", "chx", "sum", "pad")


def u8(x): return struct.pack("<B", x)
def u16(x): return struct.pack("<H", x)
def u32(x): return struct.pack("<I", x)
def u64(x): return struct.pack("<Q", x)
def string(s): b = s.encode(); return u32(len(b)) + b
def str_map(m): body = b"".join(string(k) + string(v) for k, v in m); return u32(len(body)) + body


class Builder:
    """McapRecordBuilder: records appended to one buffer, padded when asked."""

    def __init__(self, pad=False):
        self.buf = bytearray()
        self.pad = pad

    def __len__(self):
        return len(self.buf)

    def record(self, op, body, paddable=True):
        if self.pad and paddable:
            body += PAD
        start = len(self.buf)
        self.buf += u8(op) + u64(len(body)) + body
        return len(self.buf) - start

    def schema(self, r):
        return self.record(OP["Schema"], u16(r["id"]) + string(r["name"]) + string(r["encoding"])
                           + u32(len(r["data"])) + bytes(r["data"]))

    def channel(self, r):
        return self.record(OP["Channel"], u16(r["id"]) + u16(r["schema_id"]) + string(r["topic"])
                           + string(r["message_encoding"]) + str_map(r["metadata"]))

    def message(self, r):
        return self.record(OP["Message"], u16(r["channel_id"]) + u32(r["sequence"]) + u64(r["log_time"])
                           + u64(r["publish_time"]) + bytes(r["data"]), paddable=False)

    def attachment(self, r):
        body = (u64(r["log_time"]) + u64(r["create_time"]) + string(r["name"]) + string(r["media_type"])
                + u64(len(r["data"])) + bytes(r["data"]))
        return self.record(OP["Attachment"], body + u32(zlib.crc32(body)))

    def metadata(self, r):
        return self.record(OP["Metadata"], string(r["name"]) + str_map(r["metadata"]))


def typed(rec):
    """A JSON record ({"type", "fields": [[name, value]]}) as a dict of Python values."""
    out = {"type": rec["type"]}
    for name, value in rec["fields"]:
        if isinstance(value, list):
            out[name] = [int(v) for v in value]
        elif isinstance(value, dict):
            out[name] = list(value.items())
        elif name in ("name", "encoding", "topic", "message_encoding", "media_type", "library", "profile"):
            out[name] = value
        else:
            out[name] = int(value)
    return out


def generate(features, records):
    """generate-inputs.ts's generateFile."""
    b = Builder(pad="pad" in features)
    b.buf += MAGIC
    b.record(OP["Header"], string("") + string(""))
    chunk = Builder() if "ch" in features else None
    indices = {} if chunk is not None and "mx" in features else None
    chunk_times = None
    counts = dict(message=0, channel=0, schema=0, attachment=0, metadata=0)
    start_time = end_time = None
    per_channel = {}
    metadata_index, attachment_index, chunk_index = [], [], []
    for r in records:
        t = r["type"]
        if t == "Schema":
            counts["schema"] += 1
            (b if chunk is None else chunk).schema(r)
        elif t == "Channel":
            counts["channel"] += 1
            if indices is not None and r["id"] not in indices:
                indices[r["id"]] = []
            (b if chunk is None else chunk).channel(r)
        elif t == "Message":
            counts["message"] += 1
            per_channel[r["channel_id"]] = per_channel.get(r["channel_id"], 0) + 1
            if chunk is not None:
                lt = r["log_time"]
                if chunk_times is None:
                    chunk_times = [lt, lt]
                else:
                    chunk_times = [min(chunk_times[0], lt), max(chunk_times[1], lt)]
                if indices is not None:
                    indices.setdefault(r["channel_id"], []).append((lt, len(chunk)))
                chunk.message(r)
            else:
                b.message(r)
            start_time = r["log_time"] if start_time is None else min(start_time, r["log_time"])
            end_time = r["log_time"] if end_time is None else max(end_time, r["log_time"])
        elif t == "Attachment":
            counts["attachment"] += 1
            offset = len(b)
            length = b.attachment(r)
            if "ax" in features:
                attachment_index.append((offset, length, r))
        elif t == "Metadata":
            counts["metadata"] += 1
            offset = len(b)
            length = b.metadata(r)
            if "mdx" in features:
                metadata_index.append((offset, length, r["name"]))
    if chunk is not None:
        times = chunk_times or [0, 0]
        data = bytes(chunk.buf)
        chunk_start = len(b)
        chunk_length = b.record(OP["Chunk"], u64(times[0]) + u64(times[1]) + u64(len(data)) + u32(zlib.crc32(data))
                                + string("") + u64(len(data)) + data, paddable=False)
        offsets, index_length = [], 0
        for channel, entries in (indices or {}).items():
            offsets.append((channel, len(b)))
            body = u16(channel) + u32(16 * len(entries)) + b"".join(u64(a) + u64(o) for a, o in entries)
            index_length += b.record(OP["MessageIndex"], body)
        if "chx" in features:
            chunk_index.append(u64(times[0]) + u64(times[1]) + u64(chunk_start) + u64(chunk_length)
                               + u32(10 * len(offsets)) + b"".join(u16(c) + u64(o) for c, o in offsets)
                               + u64(index_length) + string("") + u64(len(data)) + u64(len(data)))
    b.record(OP["DataEnd"], u32(zlib.crc32(bytes(b.buf))), paddable=False)

    summary_start = len(b)
    groups = []

    def group(op, write):
        start = len(b)
        write()
        if len(b) != start:
            groups.append((op, start, len(b) - start))

    if "rsh" in features:
        group(OP["Schema"], lambda: [b.schema(r) for r in records if r["type"] == "Schema"])
    if "rch" in features:
        group(OP["Channel"], lambda: [b.channel(r) for r in records if r["type"] == "Channel"])
    if "st" in features:
        group(OP["Statistics"], lambda: b.record(OP["Statistics"], u64(counts["message"]) + u16(counts["schema"])
              + u32(counts["channel"]) + u32(counts["attachment"]) + u32(counts["metadata"])
              + u32(1 if chunk is not None else 0) + u64(start_time or 0) + u64(end_time or 0)
              + u32(10 * len(per_channel)) + b"".join(u16(c) + u64(n) for c, n in per_channel.items())))
    group(OP["MetadataIndex"], lambda: [b.record(OP["MetadataIndex"], u64(o) + u64(n) + string(name))
                                        for o, n, name in metadata_index])
    group(OP["AttachmentIndex"], lambda: [b.record(OP["AttachmentIndex"], u64(o) + u64(n) + u64(r["log_time"])
                                          + u64(r["create_time"]) + u64(len(r["data"])) + string(r["name"])
                                          + string(r["media_type"])) for o, n, r in attachment_index])
    group(OP["ChunkIndex"], lambda: [b.record(OP["ChunkIndex"], body) for body in chunk_index])
    has_summary = len(b) != summary_start
    summary_offset_start = 0
    if "sum" in features:
        summary_offset_start = len(b)
        for op, start, length in groups:
            b.record(OP["SummaryOffset"], u8(op) + u64(start) + u64(length))
    footer_head = u8(OP["Footer"]) + u64(20) + u64(summary_start if has_summary else 0) + u64(summary_offset_start)
    summary_crc = zlib.crc32(bytes(b.buf[summary_start:]) + footer_head)
    b.buf += footer_head + u32(summary_crc)
    b.buf += MAGIC
    return bytes(b.buf)


def git_show(repo, path):
    return subprocess.run(["git", "--git-dir", str(repo), "show", f"HEAD:{path}"], check=True,
                          capture_output=True).stdout


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repo", required=True, type=pathlib.Path, help="git directory of foxglove/mcap")
    ap.add_argument("--out", required=True, type=pathlib.Path)
    args = ap.parse_args()
    root = "tests/conformance/data"
    names = subprocess.run(["git", "--git-dir", str(args.repo), "ls-tree", "-r", "--name-only", "HEAD", root],
                           check=True, capture_output=True, text=True).stdout.split()
    mcaps = sorted(n for n in names if n.endswith(".mcap"))
    bases = {}  # base name -> the data records of its featureless variant
    for n in names:
        p = pathlib.PurePosixPath(n)
        if p.suffix == ".json" and p.stem == p.parent.name:
            recs = json.loads(git_show(args.repo, n))["records"]
            data = []
            for r in recs:
                if r["type"] == "DataEnd":
                    break
                if r["type"] != "Header":
                    data.append(typed(r))
            bases[p.stem] = data
    args.out.mkdir(parents=True, exist_ok=True)
    sums, bad, expected = [], [], {}
    for n in mcaps:
        p = pathlib.PurePosixPath(n)
        base, *features = p.stem.split("-")
        unknown = [f for f in features if f not in FEATURES]
        if base not in bases or unknown:
            bad.append(f"{n}: unknown base or features {unknown}")
            continue
        pointer = dict(line.split(" ", 1) for line in git_show(args.repo, n).decode().splitlines() if " " in line)
        oid = pointer.get("oid", "").removeprefix("sha256:")
        data = generate(set(features), bases[base])
        if hashlib.sha256(data).hexdigest() != oid or len(data) != int(pointer.get("size", -1)):
            bad.append(f"{n}: rebuilt file differs from the official one (sha256 {oid}, size {pointer.get('size')})")
            continue
        stream = []
        for r in json.loads(git_show(args.repo, str(p.with_suffix(".json"))))["records"]:
            stream.append(r)
            if r["type"] == "DataEnd":
                break
        (args.out / base).mkdir(exist_ok=True)
        (args.out / base / p.name).write_bytes(data)
        expected.setdefault(base, {})[p.stem] = stream
        sums.append(f"{oid}  {base}/{p.name}")
    for base, files in expected.items():
        text = "{\n" + ",\n".join(f"{json.dumps(k)}:{json.dumps(v, separators=(',', ':'))}" for k, v in files.items())
        (args.out / base / "expected.json").write_text(text + "\n}\n")
    (args.out / "SHA256SUMS").write_text("\n".join(sums) + "\n")
    (args.out / "LICENSE").write_bytes(git_show(args.repo, "LICENSE"))
    print(f"{len(sums)} of {len(mcaps)} conformance files rebuilt byte for byte (SHA-256 and size as in Git LFS)")
    for line in bad:
        print("  " + line, file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
