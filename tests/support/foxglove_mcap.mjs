// Reads an MCAP file as Foxglove does, with the official TypeScript library (@mcap/core) and Foxglove's
// decompressors: once through its indexed reader, once through its stream reader. Prints JSON: messages per
// topic for each reader, the opcodes of records the stream reader did not know, and the first error.
import { open } from 'node:fs/promises';
import { readFileSync } from 'node:fs';
import { McapIndexedReader, McapStreamReader } from '@mcap/core';
import * as zstd from '@foxglove/wasm-zstd';
import lz4 from '@foxglove/wasm-lz4';

await zstd.isLoaded;
await lz4.isLoaded;
const decompressHandlers = {
  zstd: (buffer, size) => zstd.decompress(buffer, Number(size)),
  lz4: (buffer, size) => lz4(buffer, Number(size)),
};

async function indexed(path) {
  const handle = await open(path, 'r');
  try {
    const readable = {
      size: async () => BigInt((await handle.stat()).size),
      read: async (offset, size) => {
        const buffer = new Uint8Array(Number(size));
        await handle.read(buffer, 0, Number(size), Number(offset));
        return buffer;
      },
    };
    const reader = await McapIndexedReader.Initialize({ readable, decompressHandlers });
    const counts = {};
    for await (const message of reader.readMessages()) {
      const topic = reader.channelsById.get(message.channelId).topic;
      counts[topic] = (counts[topic] ?? 0) + 1;
    }
    return counts;
  } finally {
    await handle.close();
  }
}

function streamed(path) {
  const reader = new McapStreamReader({ decompressHandlers, validateCrcs: true });
  reader.append(readFileSync(path));
  const topics = new Map();
  const counts = {};
  const unknown = [];
  for (let record; (record = reader.nextRecord()); ) {
    if (record.type === 'Channel') topics.set(record.id, record.topic);
    else if (record.type === 'Message') {
      const topic = topics.get(record.channelId);
      counts[topic] = (counts[topic] ?? 0) + 1;
    } else if (record.type === 'Unknown') unknown.push(record.opcode);
  }
  return { counts, unknown, done: reader.done() };
}

const out = {};
try {
  out.indexed = await indexed(process.argv[2]);
  out.stream = streamed(process.argv[2]);
} catch (error) {
  out.error = String(error);
}
process.stdout.write(JSON.stringify(out));
