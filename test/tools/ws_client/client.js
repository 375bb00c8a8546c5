// Foxglove's own WebSocket protocol client (@foxglove/ws-protocol FoxgloveClient), driven by
// the viewer's test: commands as JSON lines on stdin, events as JSON lines on stdout.
//   usage: node client.js ws://127.0.0.1:PORT
// Commands: {"op": "subscribe", "topics": [...], "count": N}  (first N messages per topic
//           shown; the subscription stays until the client closes)
//           {"op": "getParameters", "names": [...], "id": "..."}
//           {"op": "setParameters", "parameters": [{"name", "value", "type"?}], "id": "..."}
//           {"op": "subscribeParameterUpdates", "names": [...]}
//           {"op": "callService", "service": "/name", "callId": N, "data": "<base64 CDR>"}
//           {"op": "fetchAsset", "uri": "package://...", "requestId": N}
//           {"op": "close"}
// Events:   open, serverInfo, advertise (topic, schemaName, encoding, schemaEncoding,
//           schema), advertiseServices, message (topic, data base64), parameterValues,
//           status, serviceCallResponse (data base64), serviceCallFailure,
//           fetchAssetResponse (requestId, status 0 = found, data base64 / error), error, close.
"use strict";
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const WebSocket = require("ws");
const readline = require("readline");

const out = (event) => process.stdout.write(JSON.stringify(event) + "\n");
const b64 = (view) => Buffer.from(view.buffer, view.byteOffset, view.byteLength).toString("base64");

// foxglove-sdk's server (as foxglove_bridge >= 3) speaks the subprotocol foxglove.sdk.v1, the
// same protocol as foxglove.websocket.v1 under a new name; FoxgloveClient (>= 0.7.5) speaks
// whatever its WebSocket negotiated (foxglove/ws-protocol#916).
const client = new FoxgloveClient({ ws: new WebSocket(process.argv[2], ["foxglove.sdk.v1"]) });
const channels = new Map(); // topic -> channel
const services = new Map(); // name -> service
const subscriptions = new Map(); // subscription id -> {topic, left}

client.on("open", () => out({ event: "open" }));
client.on("error", (err) => out({ event: "error", message: String(err && err.message) }));
client.on("close", () => { out({ event: "close" }); process.exit(0); });
client.on("serverInfo", (info) => out({ event: "serverInfo", name: info.name,
  capabilities: info.capabilities, supportedEncodings: info.supportedEncodings }));
client.on("status", (s) => out({ event: "status", level: s.level, message: s.message }));
client.on("advertise", (list) => {
  for (const ch of list) channels.set(ch.topic, ch);
  out({ event: "advertise", channels: list.map((ch) => ({ topic: ch.topic,
    schemaName: ch.schemaName, encoding: ch.encoding, schemaEncoding: ch.schemaEncoding,
    schema: ch.schema })) });
});
client.on("advertiseServices", (list) => {
  for (const s of list) services.set(s.name, s);
  out({ event: "advertiseServices", services: list.map((s) => ({ name: s.name, type: s.type,
    request: s.request, response: s.response })) });
});
client.on("message", (m) => {
  const sub = subscriptions.get(m.subscriptionId);
  if (!sub || sub.left <= 0) return;
  sub.left -= 1;
  out({ event: "message", topic: sub.topic, timestamp: String(m.timestamp), data: b64(m.data) });
});
client.on("parameterValues", (p) => out({ event: "parameterValues", id: p.id,
  parameters: p.parameters }));
client.on("serviceCallResponse", (r) => out({ event: "serviceCallResponse", callId: r.callId,
  encoding: r.encoding, data: b64(r.data) }));
client.on("fetchAssetResponse", (r) => out({ event: "fetchAssetResponse",
  requestId: r.requestId, status: r.status, error: r.error,
  data: r.status === 0 ? b64(r.data) : undefined }));
client.on("serviceCallFailure", (f) => out({ event: "serviceCallFailure", callId: f.callId,
  message: f.message }));

readline.createInterface({ input: process.stdin }).on("line", (line) => {
  let cmd;
  try { cmd = JSON.parse(line); } catch (err) { out({ event: "error", message: "bad command: " + line }); return; }
  if (cmd.op === "subscribe") {
    for (const topic of cmd.topics) {
      const ch = channels.get(topic);
      if (!ch) { out({ event: "error", message: "not advertised: " + topic }); continue; }
      subscriptions.set(client.subscribe(ch.id), { topic, left: cmd.count || 1 });
    }
  } else if (cmd.op === "getParameters") {
    client.getParameters(cmd.names, cmd.id);
  } else if (cmd.op === "subscribeParameterUpdates") {
    client.subscribeParameterUpdates(cmd.names);
  } else if (cmd.op === "setParameters") {
    client.setParameters(cmd.parameters, cmd.id);
  } else if (cmd.op === "callService") {
    const s = services.get(cmd.service);
    if (!s) { out({ event: "error", message: "no service " + cmd.service }); return; }
    client.sendServiceCallRequest({ serviceId: s.id, callId: cmd.callId, encoding: "cdr",
      data: new Uint8Array(Buffer.from(cmd.data, "base64")) });
  } else if (cmd.op === "fetchAsset") {
    client.fetchAsset(cmd.uri, cmd.requestId);
  } else if (cmd.op === "close") {
    client.close();
  }
});
