// A Foxglove app stand-in: the official @foxglove/ws-protocol client, driven by a plan, printing what arrives as
// JSON lines. Usage: node foxglove_client.mjs WS_URL PLAN_JSON
//   plan: {subscribe: [topic...], count_topic, switch_at, switch: {name, value}, refuse_at, refuse: {name, value},
//          seek_at, seek_to, after_seek, stop_at, timeout_s}
import wsProtocol from "@foxglove/ws-protocol";
import WebSocket from "ws";

const { FoxgloveClient } = wsProtocol;
const [url, planText] = process.argv.slice(2);
const plan = JSON.parse(planText);
const out = (o) => console.log(JSON.stringify(o, (_k, v) => (typeof v === "bigint" ? v.toString() : v)));
// The SDK's server speaks "foxglove.sdk.v1", the successor of the client's "foxglove.websocket.v1" with the same
// JSON and binary messages for what is used here; the Foxglove app offers both.
// plan.open_only: offer only the client's own "foxglove.websocket.v1", as Lichtblick and ws-protocol's own
// examples do (bagfault's relay lets it in; `ws` checks the answer names what was offered).
const ws = new WebSocket(url, plan.open_only ? [FoxgloveClient.SUPPORTED_SUBPROTOCOL]
  : ["foxglove.sdk.v1", FoxgloveClient.SUPPORTED_SUBPROTOCOL]);
const client = new FoxgloveClient({ ws });
const subscriptions = new Map();
let counted = 0;
let seeked = false;
let latest = 0n;
let backwards = 0;

function finish(code) {
  out({ kind: "done", counted, backwards });
  client.close();
  setTimeout(() => process.exit(code), 100);
}
setTimeout(() => finish(2), (plan.timeout_s ?? 60) * 1000);

function seek(toNs) {
  // PlaybackControlRequest (client binary opcode 3): command u8 (0 play), speed f32, had_seek u8, seek_time u64,
  // request_id length u32 and text; little-endian, as the Foxglove SDK's protocol defines it.
  const id = Buffer.from("bagfault-test-seek");
  const buffer = Buffer.alloc(1 + 1 + 4 + 1 + 8 + 4 + id.length);
  let at = 0;
  buffer.writeUInt8(3, at); at += 1;
  buffer.writeUInt8(0, at); at += 1;
  buffer.writeFloatLE(1.0, at); at += 4;
  buffer.writeUInt8(1, at); at += 1;
  buffer.writeBigUInt64LE(BigInt(toNs), at); at += 8;
  buffer.writeUInt32LE(id.length, at); at += 4;
  id.copy(buffer, at);
  ws.send(buffer);
}

client.on("error", (error) => out({ kind: "error", message: String(error) }));
client.on("serverInfo", (info) => {
  out({ kind: "serverInfo", name: info.name, capabilities: info.capabilities, protocol: ws.protocol });
  client.getParameters([], "initial");
});
client.on("advertise", (channels) => {
  for (const channel of channels) {
    out({ kind: "channel", topic: channel.topic, encoding: channel.encoding, schemaName: channel.schemaName });
    if (plan.subscribe.includes(channel.topic)) {
      subscriptions.set(client.subscribe(channel.id), channel.topic);
    }
  }
});
client.on("parameterValues", (event) => out({ kind: "parameters", id: event.id ?? null, parameters: event.parameters }));
client.on("status", (status) => out({ kind: "status", level: status.level, message: status.message }));
client.on("message", ({ subscriptionId, timestamp, data }) => {
  const topic = subscriptions.get(subscriptionId);
  const bytes = Buffer.from(data.buffer, data.byteOffset, data.byteLength);
  out({ kind: "message", topic, t: timestamp, data: bytes.toString("base64") });
  if (topic !== plan.count_topic) return;
  if (seeked && timestamp < latest) backwards += 1;
  if (timestamp > latest) latest = timestamp;
  counted += 1;
  if (counted === plan.switch_at) {
    out({ kind: "action", action: "switch", counted });
    client.setParameters([plan.switch], "switch");
  }
  if (counted === plan.refuse_at) {
    out({ kind: "action", action: "refuse", counted });
    client.setParameters([plan.refuse], "refuse");
  }
  if (counted === plan.seek_at) {
    out({ kind: "action", action: "seek", counted });
    seeked = true;
    seek(plan.seek_to);
  }
  if (seeked && backwards >= plan.after_seek) finish(0);
  if (plan.stop_at && counted >= plan.stop_at) finish(0);
});
