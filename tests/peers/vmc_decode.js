// Decodes the first OSC packet that arrives on 127.0.0.1:PORT with the npm `osc` package
// and prints it as one JSON line: the bundle's messages, each address with its
// arguments (type tag and value; floats exactly as the float32 on the wire).
// Usage: node vmc_decode.js PORT   (prints "listening" once bound)
"use strict";
const dgram = require("dgram");
const osc = require("osc");

const port = Number(process.argv[2]);
const socket = dgram.createSocket("udp4");
socket.on("message", (data) => {
  const packet = osc.readPacket(new Uint8Array(data), { metadata: true });
  const messages = packet.packets ? packet.packets : [packet];
  const out = {
    bundle: Boolean(packet.packets),
    timetag: packet.timeTag ? packet.timeTag.raw : null,
    messages: messages.map((m) => ({ address: m.address, args: m.args.map((a) => ({ type: a.type, value: a.value })) })),
  };
  process.stdout.write(JSON.stringify(out) + "\n");
  socket.close();
});
socket.bind(port, "127.0.0.1", () => process.stdout.write("listening\n"));
setTimeout(() => {
  process.stderr.write("no packet within 20 s\n");
  process.exit(1);
}, 20000);
