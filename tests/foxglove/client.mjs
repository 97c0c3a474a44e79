// A Foxglove client, Foxglove's own (@foxglove/ws-protocol's FoxgloveClient over the `ws`
// package), run by tests/tests/foxglove.rs against a live `launch --foxglove`.
//
//   node client.mjs URL check DEADLINE_S POSES
//                                          subscribes to every channel and prints one JSON line
//                                          per event: "channel" (each advertised channel with
//                                          its schema), "pose" (a decoded foxglove.PoseInFrame),
//                                          "json" (a JSON message), "message" (any other), and
//                                          "closed" when the server goes away; exits 0 once it
//                                          has POSES poses and a margin ("done").
//   node client.mjs URL stall DEADLINE_S   subscribes to every channel, then stops reading its
//                                          socket: the slowest client there is.
//
// Protobuf messages are decoded with the schema the server advertised (a FileDescriptorSet), as
// the Foxglove app does. Every wait has a deadline: the process exits by itself.
import { createRequire } from "node:module";

// Both packages are CommonJS: loaded as Node loads them.
const require = createRequire(import.meta.url);
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");
const protobuf = require("protobufjs");
require("protobufjs/ext/descriptor");

const [url, mode, deadlineText, posesText] = process.argv.slice(2);
const wanted = Number(posesText ?? "0");
let poses = 0;
let margins = 0;
const deadline_s = Number(deadlineText ?? "60");
const print = (o) => process.stdout.write(JSON.stringify(o) + "\n");
setTimeout(() => {
  print({ event: "deadline" });
  process.exit(3);
}, deadline_s * 1000).unref();

// The SDK's server speaks `foxglove.sdk.v1`; this client knows `foxglove.websocket.v1`.
const ws = new WebSocket(url, [FoxgloveClient.SUPPORTED_SUBPROTOCOL, "foxglove.sdk.v1"]);
const client = new FoxgloveClient({ ws });
const channels = new Map();
const decoders = new Map();
let stalled = false;

client.on("error", (e) => {
  print({ event: "error", message: String(e && e.message ? e.message : e) });
});
client.on("close", () => {
  print({ event: "closed" });
  // A reading client that closes before its poses failed; a stalled one is done.
  process.exit(mode === "check" ? 4 : 0);
});
client.on("serverInfo", (info) => {
  print({ event: "server", name: info.name, capabilities: info.capabilities });
});
client.on("advertise", (list) => {
  for (const c of list) {
    print({
      event: "channel",
      topic: c.topic,
      encoding: c.encoding,
      schemaName: c.schemaName,
      schemaEncoding: c.schemaEncoding ?? null,
    });
    if (c.encoding === "protobuf") {
      const bytes = Uint8Array.from(Buffer.from(c.schema, "base64"));
      const root = protobuf.Root.fromDescriptor(bytes);
      decoders.set(c.id, root.lookupType(c.schemaName));
    }
    const sub = client.subscribe(c.id);
    channels.set(sub, c);
  }
  if (mode === "stall" && !stalled) {
    stalled = true;
    // Never read again: the server's queue for this client fills.
    setTimeout(() => ws._socket.pause(), 0);
    print({ event: "stalled" });
  }
});
client.on("message", ({ subscriptionId, data }) => {
  const c = channels.get(subscriptionId);
  if (!c) return;
  const bytes = new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
  if (c.encoding === "json") {
    print({ event: "json", topic: c.topic, value: JSON.parse(Buffer.from(bytes).toString("utf8")) });
    if (c.topic === "/cdm/audit") margins += 1;
  } else if (c.schemaName === "foxglove.PoseInFrame") {
    const m = decoders.get(c.id).decode(bytes);
    const p = m.pose.position;
    // google.protobuf.Timestamp: seconds (a Long or a number) and nanos.
    const t = m.timestamp;
    print({
      event: "pose",
      topic: c.topic,
      frame: m.frameId,
      sec: Number(t.seconds ?? 0),
      nsec: Number(t.nanos ?? 0),
      x: p.x,
      y: p.y,
      z: p.z,
    });
    poses += 1;
  } else {
    const m = decoders.get(c.id).decode(bytes);
    print({ event: "message", topic: c.topic, fields: Object.keys(m.toJSON()) });
  }
  if (mode === "check" && wanted > 0 && poses >= wanted && margins > 0) {
    print({ event: "done" });
    process.exit(0);
  }
});
