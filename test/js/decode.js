#!/usr/bin/env node
// Decode every message of MCAP files with Foxglove's own readers, as Foxglove Studio does:
// @mcap/core (indexed reader, zstd/lz4 chunks), @foxglove/rosmsg (ros2msg schema parser,
// ros2: true) and @foxglove/rosmsg2-serialization (CDR MessageReader).
//
//   node decode.js FILE.mcap [FILE.mcap ...]   -> one JSON object on stdout:
//   {"files": {FILE: {"profile", "library", "statistics": {...}, "metadata": [names],
//                     "topics": {TOPIC: {"schema", "schemaEncoding", "messageEncoding",
//                                        "count", "trailing", "errors": [..],
//                                        "step_ids": [..] (when the message has step_id),
//                                        "first": decoded first message}}}}}
// Exit code 1 when a file cannot be opened or a message cannot be decoded.
"use strict";

const fs = require("fs");
const { McapIndexedReader } = require("@mcap/core");
const { parse } = require("@foxglove/rosmsg");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");
const zstd = require("@foxglove/wasm-zstd");
const lz4 = require("@foxglove/wasm-lz4");

class FileReadable {
  constructor(path) {
    this.fd = fs.openSync(path, "r");
    this.bytes = BigInt(fs.fstatSync(this.fd).size);
  }
  async size() {
    return this.bytes;
  }
  async read(offset, size) {
    const buf = Buffer.alloc(Number(size));
    fs.readSync(this.fd, buf, 0, Number(size), Number(offset));
    return new Uint8Array(buf.buffer, buf.byteOffset, buf.byteLength);
  }
  close() {
    fs.closeSync(this.fd);
  }
}

function plain(value) {
  // JSON-able copy of a decoded message (bigint -> number, typed arrays -> arrays)
  return JSON.parse(
    JSON.stringify(value, (_k, v) => {
      if (typeof v === "bigint") return Number(v);
      if (ArrayBuffer.isView(v)) return Array.from(v, (x) => (typeof x === "bigint" ? Number(x) : x));
      return v;
    }),
  );
}

async function decodeFile(path) {
  const readable = new FileReadable(path);
  const reader = await McapIndexedReader.Initialize({
    readable,
    decompressHandlers: {
      zstd: (buf, size) => zstd.decompress(buf, Number(size)),
      lz4: (buf, size) => lz4(buf, Number(size)),
    },
  });
  const out = {
    profile: reader.header.profile,
    library: reader.header.library,
    statistics: reader.statistics
      ? {
          messageCount: Number(reader.statistics.messageCount),
          channelCount: reader.statistics.channelCount,
          schemaCount: reader.statistics.schemaCount,
          chunkCount: reader.statistics.chunkCount,
        }
      : null,
    metadata: [],
    topics: {},
  };
  for await (const m of reader.readMetadata()) out.metadata.push(m.name);
  const readers = new Map();
  for (const [id, channel] of reader.channelsById) {
    const schema = reader.schemasById.get(channel.schemaId);
    const entry = {
      schema: schema ? schema.name : null,
      schemaEncoding: schema ? schema.encoding : null,
      messageEncoding: channel.messageEncoding,
      channelMetadata: Object.fromEntries(channel.metadata),
      count: 0,
      trailing: 0,
      errors: [],
    };
    out.topics[channel.topic] = entry;
    try {
      const text = new TextDecoder().decode(schema.data);
      readers.set(id, new MessageReader(parse(text, { ros2: true })));
    } catch (err) {
      entry.errors.push(`schema: ${err.message}`);
    }
  }
  for await (const msg of reader.readMessages({ validateCrcs: true })) {
    const channel = reader.channelsById.get(msg.channelId);
    const entry = out.topics[channel.topic];
    const mr = readers.get(msg.channelId);
    entry.count += 1;
    if (!mr) continue;
    try {
      const decoded = mr.readMessage(msg.data);
      if (mr.lastReadHadTrailingBytes()) entry.trailing += 1;
      if (entry.count === 1) entry.first = plain(decoded);
      if (decoded && decoded.step_id !== undefined) {
        (entry.step_ids = entry.step_ids || []).push(Number(decoded.step_id));
      }
    } catch (err) {
      if (entry.errors.length < 5) entry.errors.push(`message ${entry.count}: ${err.message}`);
    }
  }
  readable.close();
  return out;
}

async function main() {
  await zstd.isLoaded;
  await lz4.isLoaded;
  const result = { files: {} };
  let failed = false;
  for (const path of process.argv.slice(2)) {
    try {
      result.files[path] = await decodeFile(path);
      for (const t of Object.values(result.files[path].topics)) if (t.errors.length) failed = true;
    } catch (err) {
      result.files[path] = { error: String(err && err.stack ? err.stack : err) };
      failed = true;
    }
  }
  // No process.exit(): a pipe takes 64 KiB at once and the rest of a write is queued, and
  // process.exit() drops the queue (the reader got the first 65536 characters only).
  // Setting exitCode lets node exit once stdout is flushed.
  process.exitCode = failed ? 1 : 0;
  process.stdout.write(JSON.stringify(result) + "\n");
}

main();
