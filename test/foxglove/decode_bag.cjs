// Decode every message of a rosbag2 MCAP file the way Foxglove does, with Foxglove's own
// libraries (@mcap/core's indexed reader, @foxglove/rosmsg's ROS 2 definition parser,
// @foxglove/rosmsg2-serialization's CDR reader): the check of test/test_foxglove.py.
//
//   node decode_bag.cjs FILE.mcap [TOPIC ...]
//
// Prints one JSON object: the MCAP profile, per topic the schema name and encoding, the number
// of messages decoded, how many ended in alignment padding (up to 3 bytes to a multiple of 4) and
// how many left other bytes undecoded (a schema shorter than the payload), the first error;
// and every decoded message of the TOPICs named (log time and message, uint64 as decimal strings,
// typed arrays as arrays). Exit status 0 when every message decoded.
// The libraries come from the folder in NODE_PATH (make setup installs them: tools/setup.sh).
"use strict";

const fs = require("node:fs");
const { McapIndexedReader } = require("@mcap/core");
const { parse } = require("@foxglove/rosmsg");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");
const fzstd = require("fzstd");
const lz4 = require("lz4js");

function plain(value) {
  if (typeof value === "bigint") return value.toString();
  if (ArrayBuffer.isView(value)) return Array.from(value, plain);
  if (Array.isArray(value)) return value.map(plain);
  if (value !== null && typeof value === "object") {
    const out = {};
    for (const [key, item] of Object.entries(value)) out[key] = plain(item);
    return out;
  }
  if (typeof value === "number" && !Number.isFinite(value)) return String(value);
  return value;
}

async function main() {
  const [file, ...dumpTopics] = process.argv.slice(2);
  if (!file) {
    process.stderr.write("usage: node decode_bag.cjs FILE.mcap [TOPIC ...]\n");
    return 2;
  }
  const handle = await fs.promises.open(file, "r");
  try {
    const size = BigInt((await handle.stat()).size);
    const readable = {
      size: async () => size,
      read: async (offset, length) => {
        const buffer = new Uint8Array(Number(length));
        const { bytesRead } = await handle.read(buffer, 0, Number(length), Number(offset));
        if (bytesRead !== Number(length)) throw new Error(`short read at ${offset}`);
        return buffer;
      },
    };
    const reader = await McapIndexedReader.Initialize({
      readable,
      decompressHandlers: {
        zstd: (data, decompressedSize) => fzstd.decompress(data, new Uint8Array(Number(decompressedSize))),
        lz4: (data) => lz4.decompress(data),
      },
    });
    const topics = {};
    const decoders = new Map();   // channel id -> MessageReader, or an Error
    for (const [id, channel] of reader.channelsById) {
      const schema = reader.schemasById.get(channel.schemaId);
      const entry = { schema: schema ? schema.name : "", schema_encoding: schema ? schema.encoding : "",
                      message_encoding: channel.messageEncoding, count: 0, padded: 0, undescribed_bytes: 0,
                      error: null };
      topics[channel.topic] = entry;
      try {
        if (!schema || schema.encoding !== "ros2msg" || channel.messageEncoding !== "cdr") {
          throw new Error(`not a ros2msg/cdr channel (${entry.schema_encoding}/${entry.message_encoding})`);
        }
        // what Foxglove's parseChannel does for a "ros2msg" schema
        const text = new TextDecoder().decode(schema.data);
        decoders.set(id, new MessageReader(parse(text, { ros2: true })));
      } catch (exc) {
        decoders.set(id, exc);
        entry.error = String(exc.message || exc);
      }
    }
    const dumps = Object.fromEntries(dumpTopics.map((topic) => [topic, []]));
    let total = 0;
    let failed = 0;
    for await (const message of reader.readMessages({ validateCrcs: true })) {
      total += 1;
      const channel = reader.channelsById.get(message.channelId);
      const entry = topics[channel.topic];
      const decoder = decoders.get(message.channelId);
      if (decoder instanceof Error) {
        failed += 1;
        continue;
      }
      let decoded;
      try {
        decoded = decoder.readMessage(message.data);
      } catch (exc) {
        failed += 1;
        if (!entry.error) entry.error = String(exc.message || exc);
        continue;
      }
      entry.count += 1;
      // A payload taken from DDS may end in up to 3 bytes of padding to a multiple of 4 (Fast DDS
      // pads without declaring it in the encapsulation options), which CDR readers skip; more
      // left undecoded would be data the schema does not describe.
      const size = message.data.byteLength;
      const left = size - decoder.lastReadByteLength();
      const declared = size >= 4 ? message.data[3] & 0x03 : 0;
      if (left > 0 && !(left <= declared || (left < 4 && size % 4 === 0))) entry.undescribed_bytes += 1;
      if (left > 0) entry.padded += 1;
      if (dumps[channel.topic]) dumps[channel.topic].push([message.logTime.toString(), plain(decoded)]);
    }
    const statistics = reader.statistics;
    const result = {
      profile: reader.header.profile,
      library: reader.header.library,
      statistics_message_count: statistics ? Number(statistics.messageCount) : null,
      messages: total,
      decoded: total - failed,
      failed,
      topics,
      dumps,
    };
    process.stdout.write(JSON.stringify(result) + "\n");
    return failed === 0 && Object.values(topics).every((t) => t.error === null) ? 0 : 1;
  } finally {
    await handle.close();
  }
}

main().then(
  (status) => { process.exitCode = status; },
  (exc) => { process.stderr.write(`decode_bag: ${exc && exc.stack ? exc.stack : exc}\n`); process.exitCode = 3; },
);
