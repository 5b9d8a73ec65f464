// Read MCAP files whole with Foxglove's reader stack (@mcap/core's indexed reader, zstd from
// @foxglove/wasm-zstd, ros2msg schemas parsed by @foxglove/rosmsg and CDR decoded by
// @foxglove/rosmsg2-serialization), as Foxglove opens a bag. Prints one JSON object per
// file: {path, profile, counts: {topic: n}, summary_counts: {topic: n}, first: {topic: msg}}
// and exits 1 on any error (it is printed).
"use strict";
const fs = require("fs");
const { McapIndexedReader } = require("@mcap/core");
const { parse } = require("@foxglove/rosmsg");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");
const zstd = require("@foxglove/wasm-zstd");

function fileReadable(path) {
  const fd = fs.openSync(path, "r");
  const size = BigInt(fs.fstatSync(fd).size);
  return {
    fd,
    size: async () => size,
    read: async (offset, length) => {
      const buf = Buffer.alloc(Number(length));
      fs.readSync(fd, buf, 0, Number(length), Number(offset));
      return new Uint8Array(buf.buffer, buf.byteOffset, buf.length);
    },
  };
}

function plain(value) {
  return JSON.parse(JSON.stringify(value, (_k, v) =>
    typeof v === "bigint" ? Number(v) : ArrayBuffer.isView(v) ? Array.from(v) : v));
}

async function readOne(path) {
  const readable = fileReadable(path);
  try {
    const reader = await McapIndexedReader.Initialize({
      readable,
      decompressHandlers: { zstd: (data, size) => zstd.decompress(data, Number(size)) },
    });
    const readers = new Map();
    for (const [id, channel] of reader.channelsById) {
      const schema = reader.schemasById.get(channel.schemaId);
      if (!schema || schema.encoding !== "ros2msg" || channel.messageEncoding !== "cdr") {
        throw new Error(`${channel.topic}: not ros2msg/cdr`);
      }
      const defs = parse(new TextDecoder().decode(schema.data), { ros2: true });
      readers.set(id, new MessageReader(defs));
    }
    const counts = {};
    const first = {};
    for await (const msg of reader.readMessages()) {
      const channel = reader.channelsById.get(msg.channelId);
      const decoded = readers.get(msg.channelId).readMessage(msg.data);
      counts[channel.topic] = (counts[channel.topic] || 0) + 1;
      if (!(channel.topic in first)) first[channel.topic] = plain(decoded);
    }
    const summaryCounts = {};
    for (const [id, n] of reader.statistics.channelMessageCounts) {
      summaryCounts[reader.channelsById.get(id).topic] = Number(n);
    }
    return { path, profile: reader.header.profile, counts, summary_counts: summaryCounts,
             first };
  } finally {
    fs.closeSync(readable.fd);
  }
}

(async () => {
  await zstd.isLoaded;
  let failed = false;
  for (const path of process.argv.slice(2)) {
    try {
      console.log(JSON.stringify(await readOne(path)));
    } catch (err) {
      failed = true;
      console.log(JSON.stringify({ path, error: String(err && err.stack || err) }));
    }
  }
  process.exitCode = failed ? 1 : 0;  // not process.exit(): it cuts a piped stdout short
})();
