// Minimal OpenEXR writing for the viewer tests: scanline, uncompressed, 32-bit float channels
// (OpenEXR's file layout: magic, version 2, header attributes, one offset per line, then per
// line its y, its byte count and each channel's row in the chlist's alphabetical order).
import { writeFileSync } from 'node:fs';

function attr(name, type, body) {
  const head = Buffer.from(`${name}\0${type}\0`, 'latin1');
  const size = Buffer.alloc(4);
  size.writeInt32LE(body.length, 0);
  return Buffer.concat([head, size, body]);
}

const i32s = (...v) => { const b = Buffer.alloc(4 * v.length); v.forEach((x, i) => b.writeInt32LE(x, 4 * i)); return b; };
const f32s = (...v) => { const b = Buffer.alloc(4 * v.length); v.forEach((x, i) => b.writeFloatLE(x, 4 * i)); return b; };

/** Writes {width, height, channels: {NAME: Float32Array(width*height), ...}} (row 0 = top) as
 *  an EXR file: channel names as given ('Y' for one channel; 'R', 'G', 'B' for colour). */
export function writeExr(file, { width, height, channels }) {
  const names = Object.keys(channels).sort();
  const chlist = Buffer.concat([...names.map((n) => Buffer.concat([Buffer.from(`${n}\0`, 'latin1'), i32s(2), Buffer.from([0, 0, 0, 0]), i32s(1, 1)])),
    Buffer.from([0])]);
  const header = Buffer.concat([
    Buffer.from([0x76, 0x2f, 0x31, 0x01]), i32s(2),
    attr('channels', 'chlist', chlist),
    attr('compression', 'compression', Buffer.from([0])),
    attr('dataWindow', 'box2i', i32s(0, 0, width - 1, height - 1)),
    attr('displayWindow', 'box2i', i32s(0, 0, width - 1, height - 1)),
    attr('lineOrder', 'lineOrder', Buffer.from([0])),
    attr('pixelAspectRatio', 'float', f32s(1)),
    attr('screenWindowCenter', 'v2f', f32s(0, 0)),
    attr('screenWindowWidth', 'float', f32s(1)),
    Buffer.from([0]),
  ]);
  const lineBytes = 4 * width * names.length;
  const offsets = Buffer.alloc(8 * height);
  const lines = [];
  let off = header.length + offsets.length;
  for (let y = 0; y < height; y++) {
    offsets.writeBigUInt64LE(BigInt(off), 8 * y);
    const line = Buffer.alloc(8 + lineBytes);
    line.writeInt32LE(y, 0);
    line.writeInt32LE(lineBytes, 4);
    names.forEach((n, c) => {
      for (let x = 0; x < width; x++) line.writeFloatLE(channels[n][y * width + x], 8 + 4 * (c * width + x));
    });
    lines.push(line);
    off += line.length;
  }
  writeFileSync(file, Buffer.concat([header, offsets, ...lines]));
}
