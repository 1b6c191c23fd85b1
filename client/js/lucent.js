// lucent.js: the JavaScript client of lucent/1 (protocol/PROTOCOL.md), the browser and Node
// counterpart of liblucent-client (client/lucent_client.h). An ES module without runtime
// dependencies: browsers use their WebSocket and DecompressionStream, Node >= 18 takes a
// WebSocket constructor (e.g. the `ws` package) and inflates with node:zlib.
//
// What it does: connects with subprotocol "lucent.v1", sends `hello`, waits for `welcome`;
// sends requests and matches replies by id; receives `changed` events and binary data frames,
// checks each frame (magic, version, sizes, tile table, CRC-32) and applies keyframes, tile
// deltas and residual deltas onto the client's own copy of every subscribed stream; on a
// sequence gap or a bad frame it asks the server for keyframes (`snapshot`). Optionally it
// reconnects with exponential back-off and jitter, then says hello again and resubscribes.

/**
 * The types named in these comments are declared in lucent.d.ts.
 * @typedef {import('./lucent').FrameHeader} FrameHeader
 * @typedef {import('./lucent').LightmapCopy} LightmapCopy
 * @typedef {import('./lucent').ShGridCopy} ShGridCopy
 * @typedef {import('./lucent').ObjectsCopy} ObjectsCopy
 * @typedef {import('./lucent').LucentClientOptions} LucentClientOptions
 */

/** Subprotocol offered in the WebSocket handshake (PROTOCOL.md §1.1). */
export const PROTOCOL = 'lucent.v1';

const FRAME_MAGIC = 0x3146434c; // "LCF1"
const HEADER_SIZE = 64;
const CRC_OFFSET = 60;
const OBJECT_ID_BYTES = 64;
const SH_VALUES = 27;
const STREAM_NAMES = [null, 'lightmap', 'shgrid', 'objects', 'mr.vpl'];
const ENCODING_NAMES = [null, 'rgb9e5', 'rgba16f', 'f32'];
const TEXEL_BYTES = [0, 4, 8, 12]; // lightmap texel size per encoding
const SH_VALUE_BYTES = [0, 0, 2, 4]; // one SH value per encoding (rgb9e5 is lightmap only)
const FLAG_KEYFRAME = 1;
const FLAG_DELTA = 2;
const FLAG_RESIDUAL = 4;
const FLAG_CONVERGED = 8;
const OWN_ID = 'lc~'; // ids of the library's own requests (hello, resubscriptions, resyncs)
const DEFAULT_MAX_MESSAGE = 65536; // §1.3, until the welcome states the server's limit
const MAX_QUEUED_FRAMES = 64; // frames waiting behind an asynchronous inflate
const TWO_32 = 4294967296;
const UPLOAD_MAGIC = 0x3155434c; // "LCU1" (§8.4)
const UPLOAD_HEADER_SIZE = 128;
const UPLOAD_CRC_OFFSET = 124;
const VPL_VALUES = 12; // I_d, l_d, I_s, l_s (§8.7)
const UPLOAD_ERRORS = new Set(['frame_invalid', 'frame_too_large', 'rate_limited', 'mr_not_enabled']);
const MAX_UPLOADS_IN_FLIGHT = 2; // §8.5
const LITTLE_ENDIAN = new Uint8Array(new Uint16Array([1]).buffer)[0] === 1;

// ------------------------------------------------------------------------------------------
// Errors
// ------------------------------------------------------------------------------------------

/**
 * An error of the protocol or of this library. `code` is the server's stable error code
 * (PROTOCOL.md §5.2: `unauthorized`, `forbidden`, `out_of_range`, …) for refused requests, or
 * one of the library's own: `disconnected` (the connection closed with the request in flight,
 * or there is none), `timeout`, `connect_failed`, `bad_frame` (a malformed or inapplicable data
 * frame), `resync` (a frame that needs a keyframe first: sequence gap, delta without a copy),
 * `too_large` (a server message over the limit), `bad_json`, `invalid` (a bad argument).
 */
export class LucentError extends Error {
  /**
   * @param {string} code stable error code
   * @param {string} message human text
   * @param {{pointer?: string, id?: string|number, stream?: string, reply?: object}} [extra]
   *   pointer: RFC 6901 pointer into the offending request; id: the request's id; stream: the
   *   data stream a frame error concerns; reply: the server's error message as received
   */
  constructor(code, message, extra = {}) {
    super(message);
    this.name = 'LucentError';
    /** @type {string} */
    this.code = code;
    /** @type {string|undefined} */
    this.pointer = extra.pointer;
    /** @type {string|number|undefined} */
    this.id = extra.id;
    /** @type {string|undefined} */
    this.stream = extra.stream;
    /** @type {object|undefined} */
    this.reply = extra.reply;
  }
}

function errorFromReply(msg) {
  const code = typeof msg.code === 'string' ? msg.code : 'internal';
  const text = typeof msg.message === 'string' ? msg.message : code;
  return new LucentError(code, text, { pointer: msg.pointer, id: msg.id, reply: msg });
}

// ------------------------------------------------------------------------------------------
// CRC-32 and texel decoding
// ------------------------------------------------------------------------------------------

const CRC_TABLE = (() => {
  const t = new Uint32Array(256);
  for (let n = 0; n < 256; n++) {
    let c = n;
    for (let k = 0; k < 8; k++) c = c & 1 ? 0xedb88320 ^ (c >>> 1) : c >>> 1;
    t[n] = c >>> 0;
  }
  return t;
})();

/**
 * CRC-32 (IEEE 802.3, reflected, as zlib's crc32) of `bytes`, continuing from `crc`
 * (0 to start), so crc32(b, crc32(a)) is the CRC of a followed by b.
 * @param {Uint8Array} bytes
 * @param {number} [crc=0]
 * @returns {number} unsigned 32-bit CRC
 */
export function crc32(bytes, crc = 0) {
  let c = ~crc >>> 0;
  for (let i = 0; i < bytes.length; i++) c = CRC_TABLE[(c ^ bytes[i]) & 0xff] ^ (c >>> 8);
  return ~c >>> 0;
}

// 2^(e - 15 - 9) for the 32 shared exponents of RGB9E5.
const E5_SCALE = Array.from({ length: 32 }, (_, e) => Math.pow(2, e - 24));

/**
 * Decodes one RGB9E5 texel exactly as GL's RGB9_E5 (EXT_texture_shared_exponent): bits 0–8,
 * 9–17, 18–26 the R, G, B mantissas, bits 27–31 the shared exponent, bias 15, no implicit
 * bit: value = mantissa · 2^(exponent − 24).
 * @param {number} word unsigned 32-bit texel
 * @returns {[number, number, number]} linear RGB (W/m²)
 */
export function decodeRGB9E5(word) {
  const s = E5_SCALE[word >>> 27];
  return [(word & 0x1ff) * s, ((word >>> 9) & 0x1ff) * s, ((word >>> 18) & 0x1ff) * s];
}

/**
 * IEEE 754 binary16 to a number: subnormals, infinities and NaN included.
 * @param {number} h unsigned 16-bit half float bit pattern
 * @returns {number}
 */
export function halfToFloat(h) {
  const e = (h >>> 10) & 0x1f, m = h & 0x3ff, sign = h & 0x8000 ? -1 : 1;
  if (e === 0) return sign * m * Math.pow(2, -24);
  if (e === 31) return m ? NaN : sign * Infinity;
  return sign * (1024 + m) * Math.pow(2, e - 25);
}

let halfTable = null; // all 65536 halves as float32, built on first bulk use

function halfLookup() {
  if (!halfTable) {
    halfTable = new Float32Array(65536);
    for (let h = 0; h < 65536; h++) halfTable[h] = halfToFloat(h);
  }
  return halfTable;
}

/**
 * The lightmap copy (`client.lightmap`) as float32 RGB irradiance (W/m²), W·H·3 values,
 * row 0 = top: RGB9E5 decoded exactly, RGBA16F without its alpha, f32 copied.
 * @param {{width: number, height: number, encoding: string, data: Uint32Array|Uint16Array|Float32Array}} copy
 * @param {Float32Array} [out] reused when it has W·H·3 elements
 * @returns {Float32Array}
 */
export function lightmapToFloat32(copy, out) {
  const texels = copy.width * copy.height, d = copy.data;
  if (!out || out.length !== texels * 3) out = new Float32Array(texels * 3);
  if (copy.encoding === 'rgb9e5') {
    for (let i = 0, o = 0; i < texels; i++, o += 3) {
      const w = d[i], s = E5_SCALE[w >>> 27];
      out[o] = (w & 0x1ff) * s;
      out[o + 1] = ((w >>> 9) & 0x1ff) * s;
      out[o + 2] = ((w >>> 18) & 0x1ff) * s;
    }
  } else if (copy.encoding === 'rgba16f') {
    const t = halfLookup();
    for (let i = 0, o = 0; i < texels; i++, o += 3) {
      out[o] = t[d[4 * i]];
      out[o + 1] = t[d[4 * i + 1]];
      out[o + 2] = t[d[4 * i + 2]];
    }
  } else if (copy.encoding === 'f32') {
    out.set(d.subarray(0, texels * 3));
  } else {
    throw new LucentError('invalid', `unknown lightmap encoding '${copy.encoding}'`, { pointer: '/encoding' });
  }
  return out;
}

// ------------------------------------------------------------------------------------------
// Spherical harmonics (PROTOCOL.md §2.3)
// ------------------------------------------------------------------------------------------

// The basis constants of y_i = K[i] · polynomial_i, polynomials 1, y, z, x, xy, yz, 3z²−1, xz,
// x²−y² (i = l·l + l + m), and the clamped-cosine factor A_l of each coefficient's band.
const SH_K = [
  0.28209479177387814, 0.48860251190291992, 0.48860251190291992, 0.48860251190291992, 1.09254843059207907,
  1.09254843059207907, 0.31539156525252001, 1.09254843059207907, 0.54627421529603954,
];
const SH_A = [Math.PI, (2 * Math.PI) / 3, (2 * Math.PI) / 3, (2 * Math.PI) / 3, Math.PI / 4, Math.PI / 4, Math.PI / 4,
  Math.PI / 4, Math.PI / 4];

/**
 * Irradiance E(n) = Σ c_i y_i(n) (W/m², RGB) of L2 cosine-convolved irradiance SH as the
 * shgrid and objects streams carry it: 27 values, RGB interleaved per coefficient
 * (c0.r c0.g c0.b c1.r …), real orthonormal basis, i = l·l + l + m, band 1 = √(3/4π)·(y, z, x).
 * Same as liblucent-client's lc_sh9_irradiance: `normal` need not be unit length (it is
 * normalised) and negative results (ringing) are clamped to 0.
 * @param {ArrayLike<number>} coeffs 27 values
 * @param {ArrayLike<number>} normal [nx, ny, nz] (glTF axes: right-handed, +Y up)
 * @returns {[number, number, number]}
 */
export function shIrradiance(coeffs, normal) {
  let x = normal[0], y = normal[1], z = normal[2];
  const len = Math.sqrt(x * x + y * y + z * z);
  if (len > 0) {
    x /= len;
    y /= len;
    z /= len;
  }
  const b = [1, y, z, x, x * y, y * z, 3 * z * z - 1, x * z, x * x - y * y];
  const out = [0, 0, 0];
  for (let ch = 0; ch < 3; ch++) {
    let e = 0;
    for (let i = 0; i < 9; i++) e += SH_K[i] * b[i] * coeffs[3 * i + ch];
    out[ch] = e > 0 ? e : 0;
  }
  return /** @type {[number, number, number]} */ (out);
}

/**
 * The 27 received values as three.js `SphericalHarmonics3` coefficients (what `LightProbe.sh`
 * holds): 9 [r, g, b] in lucent's coefficient order, which is three.js's. three.js stores
 * *radiance* SH in the same real orthonormal basis (`getAt` uses 0.282095, 0.488603·(y, z, x),
 * …) and convolves with the cosine lobe itself (`getIrradianceAt` and the shader's
 * `shGetIrradianceAt` multiply band l by π, 2π/3, π/4), so each band is divided by those
 * factors here (= liblucent-client's lc_sh9_to_threejs). `shGetIrradianceAt` then gives E at
 * the same normal (to three.js's 6-digit constants, ~2e-6 relative) and a Lambertian material
 * shows E·albedo/π. Axes: three.js is right-handed, +Y up, like glTF: none change. Use:
 * `probe.sh.fromArray(shToThreeCoefficients(c).flat())` or
 * `coeffs.forEach((v, i) => probe.sh.coefficients[i].fromArray(v))`.
 * @param {ArrayLike<number>} coeffs 27 values, irradiance SH (as `shIrradiance` takes)
 * @returns {Array<[number, number, number]>} 9 RGB radiance coefficients
 */
export function shToThreeCoefficients(coeffs) {
  const out = [];
  for (let i = 0; i < 9; i++) {
    const a = SH_A[i];
    out.push([coeffs[3 * i] / a, coeffs[3 * i + 1] / a, coeffs[3 * i + 2] / a]);
  }
  return out;
}

// ------------------------------------------------------------------------------------------
// Frames (PROTOCOL.md §6)
// ------------------------------------------------------------------------------------------

function badFrame(reason, stream) {
  return new LucentError('bad_frame', `bad frame: ${reason}`, { stream });
}

function u64(dv, at) {
  const lo = dv.getUint32(at, true), hi = dv.getUint32(at + 4, true);
  if (hi > 0x1fffff) throw badFrame(`a 64-bit field at byte ${at} is beyond 2^53`);
  return hi * TWO_32 + lo;
}

function toBytes(data) {
  if (data instanceof Uint8Array) return data;
  if (data instanceof ArrayBuffer) return new Uint8Array(data);
  if (ArrayBuffer.isView(data)) return new Uint8Array(data.buffer, data.byteOffset, data.byteLength);
  throw new LucentError('invalid', 'a frame is an ArrayBuffer or a typed array');
}

// Tile t covers x in [(t mod TW)·S, …+S), y in [(t div TW)·S, …+S), clipped (§6.2).
function tileRect(w, h, s, t) {
  const tw = Math.ceil(w / s), x0 = (t % tw) * s, y0 = Math.floor(t / tw) * s;
  return [x0, y0, Math.min(x0 + s, w), Math.min(y0 + s, h)];
}

function checkLightmapTiles(hd, tiles) {
  const tb = TEXEL_BYTES[hd.encodingId];
  if (!hd.tileSize) throw badFrame('a delta needs a tile size', hd.stream);
  const ntiles = Math.ceil(hd.width / hd.tileSize) * Math.ceil(hd.height / hd.tileSize);
  let bytes = 0;
  for (let i = 0; i < tiles.length; i++) {
    if (tiles[i] >= ntiles) throw badFrame('tile index outside the image', hd.stream);
    if (i && tiles[i] <= tiles[i - 1]) throw badFrame('tile indices not strictly ascending', hd.stream);
    const [x0, y0, x1, y1] = tileRect(hd.width, hd.height, hd.tileSize, tiles[i]);
    bytes += (x1 - x0) * (y1 - y0) * tb;
  }
  hd.deltaBytes = bytes;
  if (hd.residual) {
    if (!tiles.length || !hd.payloadLength) throw badFrame('an empty residual delta', hd.stream);
  } else if (bytes !== hd.payloadLength) {
    throw badFrame('payload length does not match the tiles', hd.stream);
  }
}

function checkPayload(hd, tiles) {
  if (hd.streamId === 1) {
    const tb = TEXEL_BYTES[hd.encodingId] || 0;
    if (!tb) throw badFrame('bad lightmap encoding', hd.stream);
    if (!hd.width || !hd.height || hd.depth !== 1) throw badFrame('bad lightmap dimensions', hd.stream);
    if (hd.keyframe) {
      if (hd.width * hd.height * tb !== hd.payloadLength) throw badFrame('payload length does not match the stream', hd.stream);
    } else {
      checkLightmapTiles(hd, tiles);
    }
    return;
  }
  if (hd.streamId === 4) {
    checkVplPayload(hd);
    return;
  }
  if (hd.streamId !== 2 && hd.streamId !== 3) throw badFrame(`unknown stream ${hd.streamId}`);
  const vb = SH_VALUE_BYTES[hd.encodingId] || 0;
  if (!vb) throw badFrame('bad SH encoding', hd.stream);
  if (!hd.keyframe) throw badFrame('SH streams send keyframes only', hd.stream);
  if (hd.tileSize) throw badFrame('tile size must be 0 for SH streams', hd.stream);
  let expect;
  if (hd.streamId === 2) {
    if (!hd.width || !hd.height || !hd.depth) throw badFrame('bad grid dimensions', hd.stream);
    expect = hd.width * hd.height * hd.depth * SH_VALUES * vb;
  } else {
    if (hd.height !== 1 || hd.depth !== 1) throw badFrame('objects: height and depth must be 1', hd.stream);
    expect = hd.width * (OBJECT_ID_BYTES + SH_VALUES * vb);
  }
  if (expect !== hd.payloadLength) throw badFrame('payload length does not match the stream', hd.stream);
}

// mr.vpl (§8.7): width objects, height points in all; per object 64 id bytes, u32 P, u32 0,
// P records of 12 values. Only the header's numbers are checked here; the records are walked
// in checkVplRecords once the payload is at hand.
function checkVplPayload(hd) {
  const vb = SH_VALUE_BYTES[hd.encodingId] || 0;
  if (!vb) throw badFrame('bad mr.vpl encoding (f32 or rgba16f)', hd.stream);
  if (!hd.keyframe) throw badFrame('mr.vpl sends keyframes only', hd.stream);
  if (hd.tileSize) throw badFrame('tile size must be 0 for mr.vpl', hd.stream);
  if (hd.depth !== 1) throw badFrame('mr.vpl: depth must be 1', hd.stream);
  if (hd.payloadLength !== hd.width * (OBJECT_ID_BYTES + 8) + hd.height * VPL_VALUES * vb)
    throw badFrame('mr.vpl payload length does not match objects and points', hd.stream);
}

// Walks the mr.vpl objects: each count within what is left, the counts summing to height.
function checkVplRecords(hd, payload) {
  const vb = SH_VALUE_BYTES[hd.encodingId], dv = new DataView(payload.buffer, payload.byteOffset, payload.byteLength);
  const out = [];
  let at = 0, total = 0;
  for (let i = 0; i < hd.width; i++) {
    if (at + OBJECT_ID_BYTES + 8 > payload.length) throw badFrame(`mr.vpl object ${i} runs past the payload`, hd.stream);
    const count = dv.getUint32(at + OBJECT_ID_BYTES, true), rsv = dv.getUint32(at + OBJECT_ID_BYTES + 4, true);
    if (rsv !== 0) throw badFrame(`mr.vpl object ${i}: reserved word is not 0`, hd.stream);
    const bytes = count * VPL_VALUES * vb, rec = at + OBJECT_ID_BYTES + 8;
    if (count > hd.height - total || rec + bytes > payload.length)
      throw badFrame(`mr.vpl object ${i}: ${count} points run past the payload`, hd.stream);
    out.push({ idAt: at, count, recAt: rec, bytes });
    total += count;
    at = rec + bytes;
  }
  if (total !== hd.height || at !== payload.length) throw badFrame(`mr.vpl point counts sum to ${total}, the header says ${hd.height}`, hd.stream);
  return out;
}

/**
 * Parses and checks one binary data frame (PROTOCOL.md §6.1): the 64-byte little-endian
 * header, its magic, version, header size, lengths, CRC-32, flags and the tile table against
 * the image. Throws LucentError `bad_frame` naming what is wrong. The header's flags word
 * also carries bit 3 = converged and bits 8–15 = the refinement pass (new in the server: 0 /
 * false from one that does not set them); bits 4–7 are reserved and ignored.
 * @param {ArrayBuffer|ArrayBufferView} data the frame as received
 * @returns {{header: FrameHeader, tiles: Uint32Array, payload: Uint8Array}}
 */
export function parseFrame(data) {
  const b = toBytes(data);
  if (b.length < HEADER_SIZE) throw badFrame('shorter than the 64-byte header');
  const dv = new DataView(b.buffer, b.byteOffset, b.byteLength);
  const sname = STREAM_NAMES[b[6]] || undefined; // named in errors; trusted only once the CRC is
  if (dv.getUint32(0, true) !== FRAME_MAGIC) throw badFrame('bad magic', sname);
  const version = dv.getUint16(4, true);
  if (version !== 1) throw badFrame(`unsupported version ${version}`, sname);
  if (dv.getUint16(10, true) !== HEADER_SIZE) throw badFrame('header size is not 64', sname);
  const tileCount = dv.getUint32(12, true), payloadLength = dv.getUint32(56, true);
  if (HEADER_SIZE + tileCount * 4 + payloadLength !== b.length)
    throw badFrame('length does not match tile count and payload length', sname);
  const crc = dv.getUint32(CRC_OFFSET, true);
  if (crc32(b.subarray(HEADER_SIZE), crc32(b.subarray(0, CRC_OFFSET))) !== crc) throw badFrame('CRC mismatch', sname);
  const flags = dv.getUint16(8, true), kind = flags & 7;
  const streamId = b[6], encodingId = b[7];
  /** @type {FrameHeader} */
  const hd = {
    version, streamId, stream: STREAM_NAMES[streamId] || null, encodingId, encoding: ENCODING_NAMES[encodingId] || null,
    flags, keyframe: kind === FLAG_KEYFRAME, delta: (kind & FLAG_DELTA) !== 0, residual: (kind & FLAG_RESIDUAL) !== 0,
    converged: (flags & FLAG_CONVERGED) !== 0, pass: flags >>> 8, tileCount,
    revision: u64(dv, 16), sequence: u64(dv, 24), timestamp_us: u64(dv, 32),
    width: dv.getUint32(40, true), height: dv.getUint32(44, true), depth: dv.getUint32(48, true),
    tileSize: dv.getUint32(52, true), payloadLength, crc, byteLength: b.length, applied: false,
  };
  if (kind !== FLAG_KEYFRAME && kind !== FLAG_DELTA && kind !== (FLAG_DELTA | FLAG_RESIDUAL))
    throw badFrame('flags must be keyframe, delta or delta + residual', hd.stream);
  if (hd.residual && streamId !== 1) throw badFrame('residual deltas are lightmap only', hd.stream);
  if (hd.keyframe && tileCount) throw badFrame('a keyframe has no tile table', hd.stream);
  const tiles = new Uint32Array(tileCount);
  for (let i = 0; i < tileCount; i++) tiles[i] = dv.getUint32(HEADER_SIZE + 4 * i, true);
  checkPayload(hd, tiles);
  return { header: hd, tiles, payload: b.subarray(HEADER_SIZE + 4 * tileCount) };
}

// Little-endian words of `bytes` as a new typed array (an aligned copy: received buffers
// carry no alignment guarantee).
function readWords(bytes, Type) {
  const n = bytes.length / Type.BYTES_PER_ELEMENT;
  if (LITTLE_ENDIAN) return new Type(bytes.slice().buffer, 0, n);
  const out = new Type(n), dv = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
  const get = Type === Uint16Array ? (i) => dv.getUint16(2 * i, true)
    : Type === Uint32Array ? (i) => dv.getUint32(4 * i, true) : (i) => dv.getFloat32(4 * i, true);
  for (let i = 0; i < n; i++) out[i] = get(i);
  return out;
}

function wordType(encodingId) {
  return encodingId === 1 ? Uint32Array : encodingId === 2 ? Uint16Array : Float32Array;
}

// The copy's words as unsigned integers (f32: its bit patterns), the fields residuals add to.
function wordBits(data) {
  return data instanceof Float32Array ? new Uint32Array(data.buffer, data.byteOffset, data.length) : data;
}

// new = (old + unzigzag(r)) mod 2^w per field (§6.2.1), for `count` words from `at`.
function applyResidualWords(encodingId, bits, at, res, count) {
  if (encodingId === 1) {
    for (let k = 0; k < count; k++) {
      const old = bits[at + k], r = res[k];
      let v = 0;
      for (let f = 0; f < 4; f++) {
        const off = 9 * f, mask = f === 3 ? 0x1f : 0x1ff, z = (r >>> off) & mask;
        v |= ((((old >>> off) & mask) + ((z >>> 1) ^ -(z & 1))) & mask) << off;
      }
      bits[at + k] = v >>> 0;
    }
  } else if (encodingId === 2) {
    for (let k = 0; k < count; k++) {
      const z = res[k];
      bits[at + k] = (bits[at + k] + ((z >>> 1) ^ -(z & 1))) & 0xffff;
    }
  } else {
    for (let k = 0; k < count; k++) {
      const z = res[k];
      bits[at + k] = (bits[at + k] + ((z >>> 1) ^ -(z & 1))) >>> 0;
    }
  }
}

let nodeZlibPromise;

function nodeZlib() {
  if (nodeZlibPromise === undefined) {
    const proc = globalThis.process;
    if (!proc || !proc.versions || !proc.versions.node) nodeZlibPromise = Promise.resolve(null);
    else if (typeof proc.getBuiltinModule === 'function') nodeZlibPromise = Promise.resolve(proc.getBuiltinModule('zlib'));
    else {
      const name = 'node:zlib'; // not a literal: bundlers for browsers leave it alone
      nodeZlibPromise = import(/* @vite-ignore */ name).catch(() => null);
    }
  }
  return nodeZlibPromise;
}

async function inflateWithStream(data, expected) {
  const ds = new DecompressionStream('deflate');
  const writer = ds.writable.getWriter();
  writer.write(data).catch(() => {});
  writer.close().catch(() => {});
  const reader = ds.readable.getReader(), out = new Uint8Array(expected);
  let n = 0;
  for (;;) {
    const { done, value } = await reader.read();
    if (done) break;
    if (value.length > expected - n) {
      reader.cancel().catch(() => {});
      throw new Error(`inflates to more than ${expected} bytes`);
    }
    out.set(value, n);
    n += value.length;
  }
  if (n !== expected) throw new Error(`inflates to ${n} bytes, not ${expected}`);
  return out;
}

/**
 * Inflates a zlib stream (RFC 1950) to exactly `expected` bytes (PROTOCOL.md §6.2.1): one
 * that inflates to more or fewer or is corrupt is rejected, and no more than `expected` bytes
 * are ever kept. Node: node:zlib, which also rejects bytes after the stream's end; elsewhere
 * DecompressionStream('deflate'), where trailing bytes are the browser's to refuse (Chromium
 * and Firefox do).
 * @param {Uint8Array} data
 * @param {number} expected
 * @param {{decompressionStream?: boolean}} [options] decompressionStream: use it even in Node
 * @returns {Promise<Uint8Array>}
 */
export async function inflateExact(data, expected, options = {}) {
  const zlib = options.decompressionStream ? null : await nodeZlib();
  if (!zlib) return inflateWithStream(data, expected);
  let r;
  try {
    r = zlib.inflateSync(data, { info: true, maxOutputLength: Math.max(expected, 1) });
  } catch (e) {
    throw new Error(e && e.code === 'ERR_BUFFER_TOO_LARGE' ? `inflates to more than ${expected} bytes` : String(e && e.message));
  }
  if (r.engine.bytesWritten !== data.length) throw new Error(`${data.length - r.engine.bytesWritten} bytes after the zlib stream`);
  if (r.buffer.length !== expected) throw new Error(`inflates to ${r.buffer.length} bytes, not ${expected}`);
  return new Uint8Array(r.buffer.buffer, r.buffer.byteOffset, r.buffer.length);
}

// Byte length of a string in UTF-8, stopping once it passes `cap`.
function utf8Length(s, cap) {
  if (s.length > cap) return s.length;
  if (s.length * 3 <= cap) return s.length; // fits whatever it holds; exact size not needed
  let n = 0;
  for (let i = 0; i < s.length && n <= cap; i++) {
    const c = s.charCodeAt(i);
    if (c < 0x80) n += 1;
    else if (c < 0x800) n += 2;
    else if (c >= 0xd800 && c < 0xdc00 && i + 1 < s.length) {
      n += 4;
      i++;
    } else n += 3;
  }
  return n;
}

// ------------------------------------------------------------------------------------------
// The client
// ------------------------------------------------------------------------------------------

function listen(ws, type, fn) {
  if (typeof ws.addEventListener === 'function') ws.addEventListener(type, fn);
  else ws['on' + type] = fn;
}

function validStream(s) {
  return s === 'lightmap' || s === 'shgrid' || s === 'objects' || s === 'mr.vpl';
}

/**
 * A lucent/1 connection: requests, subscriptions and the client's copy of every subscribed
 * stream. Single-threaded like the page or process it lives in; events run from the
 * WebSocket's callbacks. See client/js/README.md.
 */
export class LucentClient {
  /**
   * @param {string} url ws:// or wss:// URL of lucentd
   * @param {LucentClientOptions} [options]
   */
  constructor(url, options = {}) {
    if (typeof url !== 'string' || !/^wss?:\/\//i.test(url))
      throw new LucentError('invalid', `url '${url}' is not a ws:// or wss:// URL`, { pointer: '/url' });
    const WS = options.WebSocket || globalThis.WebSocket;
    if (typeof WS !== 'function')
      throw new LucentError('invalid', 'no WebSocket: pass options.WebSocket (e.g. the ws package in Node)', { pointer: '/WebSocket' });
    const backoff = options.backoff || {};
    /** @type {string} */
    this.url = url;
    this._WS = WS;
    this._token = options.token == null ? '' : String(options.token);
    this._name = options.client || 'lucent.js';
    this._reconnect = !!options.reconnect;
    this._initialMs = backoff.initialMs > 0 ? backoff.initialMs : 250;
    this._maxMs = backoff.maxMs >= this._initialMs ? backoff.maxMs : Math.max(8000, this._initialMs);
    this._maxRetries = options.maxRetries > 0 ? options.maxRetries : 0;
    this._timeoutMs = options.timeout > 0 ? options.timeout : 5000;
    this._maxStateBytes = options.maxStateBytes > 0 ? options.maxStateBytes : 16 << 20;
    this._capabilities = Array.isArray(options.capabilities) ? options.capabilities.map(String) : [];
    if (this._capabilities.length > 8 || this._capabilities.some((c) => !c.length || c.length > 32))
      throw new LucentError('invalid', 'capabilities: 0..8 strings of 1..32 characters', { pointer: '/capabilities' });
    /** The capabilities the welcome granted ([] when it names none). @type {string[]} */
    this.capabilities = [];
    /** The welcome's protocol version ("1.0" when it has none). @type {string|null} */
    this.protocolVersion = null;
    /** The mr.vpl copy (null until its first frame). @type {MrVplCopy|null} */
    this.mrVpl = null;
    /** The current connection's welcome message (null before the first). @type {object|null} */
    this.welcome = null;
    /** 'viewer' or 'controller' (from the welcome). @type {string|null} */
    this.role = null;
    /** The latest server revision seen in welcome, ok, changed, state and frames. @type {number} */
    this.revision = 0;
    /** The lightmap copy (null until its first keyframe). @type {LightmapCopy|null} */
    this.lightmap = null;
    /** The SH grid copy. @type {ShGridCopy|null} */
    this.shgrid = null;
    /** The objects' SH copy. @type {ObjectsCopy|null} */
    this.objects = null;
    /** Counters since construction. */
    this.stats = { frames: 0, keyframes: 0, deltas: 0, badFrames: 0, resyncs: 0, reconnects: 0, bytes: 0 };
    this._listeners = new Map();
    this._ws = null;
    this._state = 'idle'; // idle | connecting | open | waiting (to reconnect) | closed
    this._hello = null; // {resolve, reject, timer} while a hello is unanswered
    this._connecting = null; // the promise connect() returns while the first hello is unanswered
    this._pending = new Map(); // id key -> {resolve, reject, timer, type}
    this._nextId = 1;
    this._ownSeq = 0;
    this._subs = new Map(); // stream -> the subscribe message's settings
    this._stale = { lightmap: true, shgrid: true, objects: true, 'mr.vpl': true }; // needs a keyframe before deltas
    this._resyncPending = false;
    this._refused = false;
    this._closedByUser = false;
    this._attempts = 0;
    this._initial = false;
    this._helloError = null;
    this._retryTimer = null;
    this._frames = []; // {data, done} in arrival order
    this._framesBusy = false;
    this._uploads = []; // {seq, resolve, reject, timer} sent, awaiting their mr.ack (oldest first)
    this._uploadQueue = []; // {bytes, seq, resolve, reject} waiting for a free slot
  }

  /** True while a welcome was received on the open connection. @type {boolean} */
  get connected() {
    return this._state === 'open';
  }

  /**
   * Adds an event listener. Events: 'open' (socket open, hello sent), 'welcome' (welcome msg;
   * also after each reconnect), 'close' ({code, reason, reconnecting}), 'reconnecting'
   * ({attempt, delayMs, reason}), 'changed' (msg), 'object.transport' (msg: an object's clutter
   * operators started or stopped applying, PROTOCOL.md §5.5), 'state' (msg), 'error' (LucentError: bad
   * or inapplicable frames, unsolicited server errors, a failed resubscription), 'lightmap' /
   * 'shgrid' / 'objects' ((copy, header) after a frame was applied), 'frame' ((header,
   * bytes) for every frame whose header parsed, after it was handled: header.applied says
   * whether it was applied; bytes is the frame as received, for recording).
   * @param {string} event
   * @param {Function} fn
   * @returns {this}
   */
  on(event, fn) {
    if (!this._listeners.has(event)) this._listeners.set(event, new Set());
    this._listeners.get(event).add(fn);
    return this;
  }

  /**
   * Removes a listener added with on().
   * @param {string} event
   * @param {Function} fn
   * @returns {this}
   */
  off(event, fn) {
    const set = this._listeners.get(event);
    if (set) set.delete(fn);
    return this;
  }

  _emit(event, ...args) {
    const set = this._listeners.get(event);
    if (!set) return;
    for (const fn of [...set]) {
      try {
        fn(...args);
      } catch (e) {
        queueMicrotask(() => {
          throw e; // a listener's fault surfaces as an uncaught error, not as the client's
        });
      }
    }
  }

  /**
   * Connects and completes hello/welcome. Resolves with the welcome message; rejects with
   * LucentError: the server's code when it refused the hello (e.g. `unauthorized`: never
   * retried), `connect_failed` or `timeout`. Like liblucent-client, a failed first connection
   * is not retried; `reconnect` applies to connections lost after a welcome.
   * @returns {Promise<object>}
   */
  connect() {
    if (this._state === 'open') return Promise.resolve(this.welcome);
    if (this._connecting) return this._connecting;
    if (this._state === 'waiting' || this._state === 'connecting')
      return Promise.reject(new LucentError('invalid', 'already reconnecting'));
    this._closedByUser = false;
    this._refused = false;
    this._helloError = null;
    this._initial = true; // a failed first connection is not retried
    this._connecting = this._open().then(
      (welcome) => {
        this._initial = false;
        this._connecting = null;
        return welcome;
      },
      (err) => {
        this._initial = false;
        this._connecting = null;
        if (this._state === 'connecting') this._abandonSocket();
        throw err;
      },
    );
    return this._connecting;
  }

  // Drops the socket of a failed first connection: its later events are ignored.
  _abandonSocket() {
    const ws = this._ws;
    this._ws = null;
    this._state = 'idle';
    try {
      if (ws) ws.close();
    } catch (e) {
      /* closing a socket that never opened */
    }
  }

  _open() {
    return new Promise((resolve, reject) => {
      this._state = 'connecting';
      let ws;
      try {
        ws = new this._WS(this.url, PROTOCOL);
      } catch (e) {
        this._state = 'idle';
        reject(new LucentError('connect_failed', `cannot connect to ${this.url}: ${e && e.message}`));
        return;
      }
      ws.binaryType = 'arraybuffer';
      this._ws = ws;
      const timer = setTimeout(() => {
        this._failHello(new LucentError('timeout', `no welcome from ${this.url} within ${this._timeoutMs} ms`));
        try {
          ws.close();
        } catch (e) {
          /* closing a socket that never opened */
        }
      }, this._timeoutMs);
      this._hello = { resolve, reject, timer, error: null, id: `${OWN_ID}hello-${++this._ownSeq}` };
      let lastError = '';
      listen(ws, 'open', () => {
        if (this._ws !== ws) return;
        this._emit('open');
        this._sendRaw({ type: 'hello', id: this._hello ? this._hello.id : `${OWN_ID}hello`, client: this._name,
          token: this._token, encodings: ['rgb9e5', 'rgba16f', 'f32'],
          ...(this._capabilities.length ? { capabilities: this._capabilities } : {}) });
      });
      listen(ws, 'message', (ev) => {
        if (this._ws === ws) this._onMessage(ev.data);
      });
      listen(ws, 'error', (ev) => {
        lastError = (ev && (ev.message || (ev.error && ev.error.message))) || 'WebSocket error';
      });
      listen(ws, 'close', (ev) => {
        if (this._ws !== ws) return;
        this._onClose(ev && ev.code, (ev && ev.reason) || lastError || 'connection closed');
      });
    });
  }

  _failHello(err) {
    const h = this._hello;
    if (!h) return;
    this._hello = null;
    clearTimeout(h.timer);
    h.reject(err);
  }

  _sendRaw(msg) {
    try {
      this._ws.send(JSON.stringify(msg));
      return true;
    } catch (e) {
      return false;
    }
  }

  _onClose(code, reason) {
    const wasOpen = this._state === 'open';
    this._ws = null;
    if (this._hello) {
      const h = this._hello;
      this._failHello(h.error || new LucentError('connect_failed', `cannot connect to ${this.url}: ${reason} (${code})`));
    }
    this._rejectPending(reason);
    this._rejectUploads(reason);
    if (this._state === 'closed') return;
    if (this._initial) {
      this._state = 'idle';
      return;
    }
    const retry = this._reconnect && !this._refused && !this._closedByUser &&
      (!this._maxRetries || this._attempts + (wasOpen ? 0 : 1) < this._maxRetries);
    if (wasOpen) this._emit('close', { code, reason, reconnecting: retry });
    if (!retry) {
      this._state = 'closed';
      if (!wasOpen) {
        // a reconnect attempt failed for good: refused, or the retries are spent
        this._emit('error', this._helloError ||
          new LucentError('connect_failed', `gave up reconnecting after ${this._attempts + 1} attempts: ${reason}`));
        this._emit('close', { code, reason, reconnecting: false });
      }
      return;
    }
    if (wasOpen) this.stats.reconnects++;
    else this._attempts++;
    const base = Math.min(this._maxMs, this._initialMs * Math.pow(2, Math.min(this._attempts, 30)));
    const delayMs = Math.round(base * (0.8 + 0.4 * Math.random())); // jitter: clients do not retry in step
    this._state = 'waiting';
    this._emit('reconnecting', { attempt: this._attempts + 1, delayMs, reason });
    this._retryTimer = setTimeout(() => {
      this._retryTimer = null;
      if (this._state !== 'waiting') return;
      this._open().catch(() => {}); // a failure closes the socket, which schedules the next try
    }, delayMs);
  }

  _rejectPending(reason) {
    const pending = [...this._pending.values()];
    this._pending.clear();
    for (const p of pending) {
      clearTimeout(p.timer);
      p.reject(new LucentError('disconnected', `connection closed before the reply: ${reason}`, { id: p.id }));
    }
  }

  /**
   * Closes the connection for good (no reconnect); requests in flight reject with
   * `disconnected`. Emits 'close' when a connection was open.
   */
  close() {
    const wasOpen = this._state === 'open';
    this._closedByUser = true;
    this._state = 'closed';
    if (this._retryTimer) clearTimeout(this._retryTimer);
    this._retryTimer = null;
    const ws = this._ws;
    this._ws = null;
    this._failHello(new LucentError('disconnected', 'closed by the client'));
    this._rejectPending('closed by the client');
    this._rejectUploads('closed by the client');
    if (ws) {
      try {
        ws.close(1000, 'bye');
      } catch (e) {
        /* already closing */
      }
    }
    if (wasOpen) this._emit('close', { code: 1000, reason: 'closed by the client', reconnecting: false });
  }

  _onMessage(data) {
    if (typeof data === 'string') this._onText(data);
    else if (typeof Blob !== 'undefined' && data instanceof Blob) data.arrayBuffer().then((b) => this._queueFrame(b, null));
    else this._queueFrame(data, null);
  }

  _textLimit() {
    const lim = this.welcome && this.welcome.limits && this.welcome.limits.max_message;
    const base = lim > 0 ? lim : DEFAULT_MAX_MESSAGE;
    // A state reply is as large as the scene; lucentd does not hold it to max_message.
    for (const p of this._pending.values()) if (p.type === 'state.get') return Math.max(base, this._maxStateBytes);
    return base;
  }

  _onText(text) {
    const limit = this._textLimit(), n = utf8Length(text, limit);
    if (n > limit) {
      this._emit('error', new LucentError('too_large', `server message of ${n}+ bytes is over the limit of ${limit}`));
      return;
    }
    let msg;
    try {
      msg = JSON.parse(text);
    } catch (e) {
      msg = null;
    }
    if (!msg || typeof msg !== 'object' || Array.isArray(msg)) {
      this._emit('error', new LucentError('bad_json', 'server message is not a JSON object'));
      return;
    }
    const type = msg.type, id = msg.id;
    if (this._hello && this._state === 'connecting') {
      if (type === 'welcome') this._onWelcome(msg);
      else if (type === 'error') {
        this._refused = true; // a refused hello (unauthorized, …) is not retried
        this._helloError = this._hello.error = errorFromReply(msg);
        this._failHello(this._hello.error);
      }
      return;
    }
    if ((type === 'ok' || type === 'changed' || type === 'state') && Number.isSafeInteger(msg.revision))
      this.revision = Math.max(this.revision, msg.revision);
    if (type === 'changed') this._emit('changed', msg);
    if (type === 'object.transport') this._emit('object.transport', msg);
    if (type === 'mr.ack') {
      this._onAck(msg);
      return;
    }
    if (type === 'error' && id === undefined && UPLOAD_ERRORS.has(msg.code) && this._uploads.length) {
      const u = this._uploads.shift();
      clearTimeout(u.timer);
      u.reject(errorFromReply(msg));
      this._pumpUploads();
      return;
    }
    if (type === 'state') this._emit('state', msg);
    if (typeof id === 'string' && id.startsWith(OWN_ID)) {
      if (id.startsWith(`${OWN_ID}resync-`)) this._resyncPending = false;
      if (type === 'error') this._emit('error', errorFromReply(msg));
      return;
    }
    const key = id === undefined ? undefined : this._idKey(id);
    const p = key === undefined ? undefined : this._pending.get(key);
    if (p && (type === 'ok' || type === 'state' || type === 'pong' || type === 'error' || type === 'welcome')) {
      this._pending.delete(key);
      clearTimeout(p.timer);
      if (type === 'error') p.reject(errorFromReply(msg));
      else p.resolve(msg);
    } else if (type === 'error') {
      this._emit('error', errorFromReply(msg));
    }
  }

  _onWelcome(msg) {
    const h = this._hello;
    this._hello = null;
    clearTimeout(h.timer);
    this.welcome = msg;
    this.role = typeof msg.role === 'string' ? msg.role : null;
    this.capabilities = Array.isArray(msg.capabilities) ? msg.capabilities.filter((c) => typeof c === 'string') : [];
    this.protocolVersion = typeof msg.version === 'string' ? msg.version : '1.0';
    this.revision = Number.isSafeInteger(msg.revision) ? msg.revision : 0;
    this._state = 'open';
    this._attempts = 0;
    this._resyncPending = false;
    this._stale = { lightmap: true, shgrid: true, objects: true, 'mr.vpl': true }; // sequences start again at 1
    for (const [stream, settings] of this._subs)
      this._sendRaw({ type: 'subscribe', id: `${OWN_ID}sub-${stream}-${++this._ownSeq}`, stream, ...settings });
    this._emit('welcome', msg);
    h.resolve(msg);
  }

  _idKey(id) {
    return (typeof id === 'number' ? 'n:' : 's:') + String(id);
  }

  /**
   * Sends one request and resolves with its reply (`ok`, `state`, `pong`), matched by id: an
   * integer id is assigned when the message has none. Rejects with LucentError: the server's
   * `error` (code, message, pointer, id), `timeout` (options.timeout ms, default the
   * client's), `disconnected` (no connection, or it closed first), `too_large` (over the
   * server's max_message: not sent, since the server would close the connection), `invalid`
   * (not an object, or an id already in flight).
   * @param {object} msg e.g. {type: 'light.set', light: {...}}
   * @param {{timeout?: number}} [options]
   * @returns {Promise<object>}
   */
  request(msg, options = {}) {
    if (!msg || typeof msg !== 'object' || Array.isArray(msg))
      return Promise.reject(new LucentError('invalid', 'a request is a JSON object', { pointer: '' }));
    if (this._state !== 'open' || !this._ws) return Promise.reject(new LucentError('disconnected', 'not connected', { id: msg.id }));
    let id = msg.id;
    if (id === undefined) {
      do id = this._nextId++;
      while (this._pending.has(this._idKey(id)));
      msg = { ...msg, id };
    } else if (!(typeof id === 'string' && id.length && !id.startsWith(OWN_ID)) && !(Number.isSafeInteger(id) && id >= 0)) {
      return Promise.reject(new LucentError('invalid', 'id must be a string (not starting with lc~) or an integer >= 0', { pointer: '/id' }));
    }
    const key = this._idKey(id);
    if (this._pending.has(key)) return Promise.reject(new LucentError('invalid', `a request with id ${id} is in flight`, { pointer: '/id', id }));
    const text = JSON.stringify(msg), limit = (this.welcome.limits && this.welcome.limits.max_message) || DEFAULT_MAX_MESSAGE;
    const bytes = utf8Length(text, limit);
    if (bytes > limit)
      return Promise.reject(new LucentError('too_large', `request of ${bytes}+ bytes is over the server's limit of ${limit}`, { pointer: '', id }));
    const timeoutMs = options.timeout > 0 ? options.timeout : this._timeoutMs;
    return new Promise((resolve, reject) => {
      const timer = setTimeout(() => {
        this._pending.delete(key);
        reject(new LucentError('timeout', `no reply to ${msg.type} (id ${id}) within ${timeoutMs} ms`, { id }));
      }, timeoutMs);
      this._pending.set(key, { resolve, reject, timer, id, type: msg.type });
      try {
        this._ws.send(text);
      } catch (e) {
        this._pending.delete(key);
        clearTimeout(timer);
        reject(new LucentError('disconnected', `cannot send: ${e && e.message}`, { id }));
      }
    });
  }

  /**
   * Subscribes to a stream (PROTOCOL.md §4.1) and resolves with the server's ok; a keyframe
   * follows. The settings are remembered and sent again after a reconnect; subscribing again
   * replaces them.
   * @param {'lightmap'|'shgrid'|'objects'|'mr.vpl'} stream
   * @param {{encoding?: 'rgb9e5'|'rgba16f'|'f32', delta?: 'tiles'|'residual', max_rate?: number, timeout?: number}} [options]
   *   encoding: the server's default when absent (lightmap rgb9e5, SH f32); delta: lightmap only
   * @returns {Promise<object>}
   */
  async subscribe(stream, options = {}) {
    if (!validStream(stream))
      throw new LucentError('invalid', `stream '${stream}' is not lightmap, shgrid, objects or mr.vpl`, { pointer: '/stream' });
    const settings = {};
    if (options.encoding !== undefined) settings.encoding = options.encoding;
    if (options.delta !== undefined) settings.delta = options.delta;
    if (options.max_rate !== undefined) settings.max_rate = options.max_rate;
    const ok = await this.request({ type: 'subscribe', stream, ...settings }, { timeout: options.timeout });
    this._subs.set(stream, settings);
    return ok;
  }

  /**
   * Ends a subscription (its copy stays as it was) and resolves with the ok.
   * @param {'lightmap'|'shgrid'|'objects'|'mr.vpl'} stream
   * @returns {Promise<object>}
   */
  async unsubscribe(stream) {
    if (!validStream(stream))
      throw new LucentError('invalid', `stream '${stream}' is not lightmap, shgrid, objects or mr.vpl`, { pointer: '/stream' });
    this._subs.delete(stream);
    return this.request({ type: 'unsubscribe', stream });
  }

  /** Asks for a keyframe of every subscribed stream (§4.12); resolves with the ok. @returns {Promise<object>} */
  snapshot() {
    return this.request({ type: 'snapshot' });
  }

  /** The server's state (§5.4): lights, objects, materials, environment, settings. @returns {Promise<object>} */
  state() {
    return this.request({ type: 'state.get' });
  }

  /**
   * Round trip: resolves with the pong, plus `rtt_ms` measured here.
   * @param {number} [t] echoed by the server (default: a local clock in ms)
   * @returns {Promise<object>}
   */
  async ping(t) {
    const now = () => (globalThis.performance ? globalThis.performance.now() : Date.now());
    const t0 = now();
    const pong = await this.request({ type: 'ping', t: t === undefined ? t0 : t });
    return { ...pong, rtt_ms: now() - t0 };
  }

  /**
   * Checks and applies one binary data frame as if it had arrived on the socket (tests,
   * replays, other transports), in order with the received ones. Resolves true when it was
   * applied; false when it was rejected (an 'error' event says why and, for a bad or
   * inapplicable frame, a `snapshot` was requested).
   * @param {ArrayBuffer|ArrayBufferView} data
   * @returns {Promise<boolean>}
   */
  handleFrame(data) {
    return new Promise((resolve) => this._queueFrame(data, resolve));
  }

  _queueFrame(data, done) {
    if (this._frames.length >= MAX_QUEUED_FRAMES) {
      for (const f of this._frames.splice(0)) if (f.done) f.done(false);
      this._stale = { lightmap: true, shgrid: true, objects: true, 'mr.vpl': true };
      this._resync(new LucentError('resync', `over ${MAX_QUEUED_FRAMES} frames waiting: dropped, keyframes requested`));
    }
    this._frames.push({ data, done });
    if (!this._framesBusy) this._drainFrames();
  }

  async _drainFrames() {
    this._framesBusy = true;
    while (this._frames.length) {
      const f = this._frames.shift();
      let ok = false;
      try {
        ok = await this._applyFrame(f.data);
      } catch (e) {
        this._emit('error', e instanceof LucentError ? e : new LucentError('bad_frame', String(e && e.message)));
      }
      if (f.done) f.done(ok);
    }
    this._framesBusy = false;
  }

  // Marks `stream` (or every stream) as needing a keyframe, asks for one and says why.
  _resync(err, stream) {
    if (stream) this._stale[stream] = true;
    this._emit('error', err);
    if (this._resyncPending || this._state !== 'open') return;
    if (this._sendRaw({ type: 'snapshot', id: `${OWN_ID}resync-${++this._ownSeq}` })) {
      this._resyncPending = true;
      this.stats.resyncs++;
    }
  }

  async _applyFrame(data) {
    const bytes = toBytes(data);
    this.stats.bytes += bytes.length;
    let parsed;
    try {
      parsed = parseFrame(bytes);
    } catch (e) {
      this.stats.badFrames++;
      const s = STREAM_NAMES[bytes.length > 6 ? bytes[6] : 0];
      if (s) this._stale[s] = true;
      else this._stale = { lightmap: true, shgrid: true, objects: true, 'mr.vpl': true };
      this._resync(e instanceof LucentError ? e : badFrame(String(e)), s || undefined);
      return false;
    }
    const hd = parsed.header;
    let ok;
    try {
      ok = hd.streamId === 1 ? await this._applyLightmap(parsed) : hd.streamId === 4 ? this._applyVpl(parsed) : this._applySh(parsed);
    } catch (e) {
      if (!(e instanceof LucentError)) throw e;
      if (e.code === 'bad_frame') this.stats.badFrames++;
      this._resync(e, hd.stream);
      ok = false;
    }
    hd.applied = ok;
    if (ok) {
      this.stats.frames++;
      if (hd.keyframe) {
        this.stats.keyframes++;
        this._resyncPending = false;
      } else this.stats.deltas++;
      this.revision = Math.max(this.revision, hd.revision);
    }
    this._emit('frame', hd, bytes);
    if (ok) this._emit(hd.stream, hd.streamId === 4 ? this.mrVpl : this[hd.stream], hd);
    return ok;
  }

  // A frame that breaks a limit the welcome states cannot be fixed by a keyframe: it is
  // dropped with an 'error', and no snapshot is asked for (it would only repeat).
  _capError(reason, stream) {
    this.stats.badFrames++;
    this._stale[stream] = true;
    this._emit('error', badFrame(reason, stream));
    return false;
  }

  async _applyLightmap({ header: hd, tiles, payload }) {
    const lm = this.welcome && this.welcome.scene && this.welcome.scene.lightmap;
    if (!lm || hd.width !== lm.width || hd.height !== lm.height)
      return this._capError(`lightmap ${hd.width}x${hd.height} is not the welcome's ${lm ? `${lm.width}x${lm.height}` : '(none)'}`, 'lightmap');
    const Type = wordType(hd.encodingId);
    if (hd.keyframe) {
      this.lightmap = {
        width: hd.width, height: hd.height, tile: hd.tileSize, encoding: hd.encoding, data: readWords(payload, Type),
        revision: hd.revision, sequence: hd.sequence, pass: hd.pass, converged: hd.converged,
        timestamp_us: hd.timestamp_us, tiles: null,
      };
      this._stale.lightmap = false;
      return true;
    }
    const copy = this.lightmap;
    this._checkDelta(hd, copy);
    if (copy.width !== hd.width || copy.height !== hd.height || copy.encoding !== hd.encoding)
      throw new LucentError('resync', `a ${hd.encoding} delta for a ${hd.width}x${hd.height} lightmap, the copy is ${copy.encoding} ${copy.width}x${copy.height}`, { stream: 'lightmap' });
    const tb = TEXEL_BYTES[hd.encodingId], per = tb / Type.BYTES_PER_ELEMENT;
    let src = payload;
    if (hd.residual) {
      try {
        src = await inflateExact(payload, hd.deltaBytes);
      } catch (e) {
        throw badFrame(`the residual payload does not inflate to ${hd.deltaBytes} bytes: ${e.message}`, 'lightmap');
      }
      if (this.lightmap !== copy) throw new LucentError('resync', 'the lightmap copy changed during an inflate', { stream: 'lightmap' });
    }
    const words = readWords(src, hd.residual ? (Type === Float32Array ? Uint32Array : Type) : Type);
    const dst = hd.residual ? wordBits(copy.data) : copy.data;
    let k = 0;
    for (const t of tiles) {
      const [x0, y0, x1, y1] = tileRect(hd.width, hd.height, hd.tileSize, t), n = (x1 - x0) * per;
      for (let y = y0; y < y1; y++, k += n) {
        const at = (y * hd.width + x0) * per;
        if (hd.residual) applyResidualWords(hd.encodingId, dst, at, words.subarray(k, k + n), n);
        else dst.set(words.subarray(k, k + n), at);
      }
    }
    Object.assign(copy, { revision: hd.revision, sequence: hd.sequence, pass: hd.pass, converged: hd.converged,
      timestamp_us: hd.timestamp_us, tile: hd.tileSize, tiles });
    return true;
  }

  _checkDelta(hd, copy) {
    if (!copy || this._stale[hd.stream])
      throw new LucentError('resync', `${hd.stream} delta (sequence ${hd.sequence}) without a keyframe before it`, { stream: hd.stream });
    if (hd.revision < copy.revision)
      throw badFrame(`revision went back from ${copy.revision} to ${hd.revision}`, hd.stream);
    if (hd.sequence !== copy.sequence + 1) {
      this._stale[hd.stream] = true;
      throw new LucentError('resync', `${hd.stream} sequence gap: ${hd.sequence} after ${copy.sequence}`, { stream: hd.stream });
    }
  }

  _shValues(bytes, encodingId) {
    if (encodingId === 3) return readWords(bytes, Float32Array);
    const halves = readWords(bytes, Uint16Array), t = halfLookup(), out = new Float32Array(halves.length);
    for (let i = 0; i < halves.length; i++) out[i] = t[halves[i]];
    return out;
  }

  _applySh({ header: hd, payload }) {
    const w = this.welcome || {}, scene = w.scene || {};
    const prev = this[hd.stream];
    if (prev && !this._stale[hd.stream] && hd.revision < prev.revision)
      throw badFrame(`revision went back from ${prev.revision} to ${hd.revision}`, hd.stream);
    const meta = { revision: hd.revision, sequence: hd.sequence, pass: hd.pass, converged: hd.converged, timestamp_us: hd.timestamp_us };
    if (hd.streamId === 2) {
      const g = scene.grid, dims = g && g.dims;
      if (!dims || dims[0] !== hd.width || dims[1] !== hd.height || dims[2] !== hd.depth)
        return this._capError(`grid ${hd.width}x${hd.height}x${hd.depth} is not the welcome's ${dims ? dims.join('x') : '(none)'}`, 'shgrid');
      this.shgrid = { dims: [hd.width, hd.height, hd.depth], origin: g.origin, cell: g.cell,
        data: this._shValues(payload, hd.encodingId), ...meta };
    } else {
      const max = w.limits && w.limits.max_objects;
      if (!(hd.width <= max)) return this._capError(`${hd.width} objects, over the welcome's max_objects ${max}`, 'objects');
      const vb = SH_VALUE_BYTES[hd.encodingId], rec = OBJECT_ID_BYTES + SH_VALUES * vb, ids = [], byId = new Map();
      const dec = new TextDecoder('utf-8');
      for (let i = 0; i < hd.width; i++) {
        const at = i * rec, idBytes = payload.subarray(at, at + OBJECT_ID_BYTES);
        const end = idBytes.indexOf(0);
        const id = dec.decode(end < 0 ? idBytes : idBytes.subarray(0, end));
        ids.push(id);
        byId.set(id, this._shValues(payload.subarray(at + OBJECT_ID_BYTES, at + rec), hd.encodingId));
      }
      this.objects = { ids, byId, ...meta };
    }
    this._stale[hd.stream] = false;
    return true;
  }

  // ----------------------------------------------------------------------------------------
  // MR sessions (PROTOCOL.md §8)
  // ----------------------------------------------------------------------------------------

  /**
   * Opens (or replaces) the connection's MR session (§8.2) and resolves with the ok's `mr`:
   * {session, max_frame, max_rate, max_lights, points}. Rejects with LucentError
   * (mr_not_enabled, unknown_id, invalid / out_of_range with a pointer, …).
   * @param {object} session {objects, width, height, depth, color, max_rate?, glossy?, …}
   * @param {{timeout?: number}} [options]
   * @returns {Promise<object>}
   */
  async mrBegin(session, options = {}) {
    if (!session || typeof session !== 'object' || Array.isArray(session))
      throw new LucentError('invalid', 'session is an object', { pointer: '/session' });
    const ok = await this.request({ type: 'mr.begin', session }, options);
    if (!ok.mr || typeof ok.mr !== 'object') throw new LucentError('bad_reply', 'mr.begin ok without "mr"', { pointer: '/mr' });
    return ok.mr;
  }

  /** Ends the MR session (§8.3); resolves with the ok (also when none was open). @returns {Promise<object>} */
  mrEnd(options = {}) {
    return this.request({ type: 'mr.end' }, options);
  }

  /**
   * Sends one upload frame (§8.4, e.g. from encodeUploadFrame) and resolves with its mr.ack
   * ({seq, capture_us, status, lights, ms}). At most 2 frames are unacknowledged: a third
   * waits here until an ack frees a slot. An error without id for an upload (frame_invalid,
   * frame_too_large, rate_limited, mr_not_enabled) rejects the oldest unacknowledged send.
   * @param {Uint8Array} bytes
   * @param {{timeout?: number}} [options] ms to wait for the ack once sent (default the client's)
   * @returns {Promise<object>}
   */
  sendUploadFrame(bytes, options = {}) {
    let b;
    try {
      b = toBytes(bytes);
    } catch (e) {
      return Promise.reject(new LucentError('invalid', 'an upload frame is a typed array or ArrayBuffer', { pointer: '/frame' }));
    }
    if (b.length < UPLOAD_HEADER_SIZE || new DataView(b.buffer, b.byteOffset, 8).getUint32(0, true) !== UPLOAD_MAGIC)
      return Promise.reject(new LucentError('invalid', 'not an LCU1 upload frame', { pointer: '/frame/magic' }));
    if (this._state !== 'open' || !this._ws) return Promise.reject(new LucentError('disconnected', 'not connected'));
    const seq = new DataView(b.buffer, b.byteOffset, 16).getUint32(12, true);
    const timeoutMs = options.timeout > 0 ? options.timeout : this._timeoutMs;
    return new Promise((resolve, reject) => {
      this._uploadQueue.push({ bytes: b, seq, resolve, reject, timeoutMs });
      this._pumpUploads();
    });
  }

  _pumpUploads() {
    while (this._uploads.length < MAX_UPLOADS_IN_FLIGHT && this._uploadQueue.length) {
      const q = this._uploadQueue.shift();
      if (this._state !== 'open' || !this._ws) {
        q.reject(new LucentError('disconnected', 'not connected'));
        continue;
      }
      const u = { seq: q.seq, resolve: q.resolve, reject: q.reject, timer: null };
      u.timer = setTimeout(() => {
        const i = this._uploads.indexOf(u);
        if (i >= 0) this._uploads.splice(i, 1);
        u.reject(new LucentError('timeout', `no mr.ack for upload ${u.seq} within ${q.timeoutMs} ms`));
        this._pumpUploads();
      }, q.timeoutMs);
      this._uploads.push(u);
      try {
        this._ws.send(q.bytes);
      } catch (e) {
        this._uploads.pop();
        clearTimeout(u.timer);
        u.reject(new LucentError('disconnected', `cannot send: ${e && e.message}`));
      }
    }
  }

  _onAck(msg) {
    const i = this._uploads.findIndex((u) => u.seq === msg.seq);
    if (i >= 0) {
      const [u] = this._uploads.splice(i, 1);
      clearTimeout(u.timer);
      u.resolve(msg);
    }
    this._emit('mr.ack', msg);
    this._pumpUploads();
  }

  _rejectUploads(reason) {
    const all = [...this._uploads, ...this._uploadQueue];
    this._uploads = [];
    this._uploadQueue = [];
    for (const u of all) {
      clearTimeout(u.timer);
      u.reject(new LucentError('disconnected', `connection closed before the mr.ack: ${reason}`));
    }
  }

  _applyVpl({ header: hd, payload }) {
    const prev = this.mrVpl;
    if (prev && !this._stale['mr.vpl'] && hd.revision < prev.revision)
      throw badFrame(`revision went back from ${prev.revision} to ${hd.revision}`, hd.stream);
    const parts = checkVplRecords(hd, payload), dec = new TextDecoder('utf-8'), objects = [], byId = new Map();
    for (const p of parts) {
      const idBytes = payload.subarray(p.idAt, p.idAt + OBJECT_ID_BYTES), end = idBytes.indexOf(0);
      const id = dec.decode(end < 0 ? idBytes : idBytes.subarray(0, end));
      const o = { id, count: p.count, records: this._shValues(payload.subarray(p.recAt, p.recAt + p.bytes), hd.encodingId) };
      objects.push(o);
      byId.set(id, o);
    }
    this.mrVpl = { objects, byId, encoding: hd.encoding, points: hd.height, revision: hd.revision, sequence: hd.sequence,
      timestamp_us: hd.timestamp_us };
    this._stale['mr.vpl'] = false;
    return true;
  }
}

// ------------------------------------------------------------------------------------------
// Upload frames (PROTOCOL.md §8.4)
// ------------------------------------------------------------------------------------------

const DEPTH_ENCODINGS = { u16mm: 1, f16m: 2 };
const COLOR_ENCODINGS = { rgb8_srgb: 1, rgb16f_linear: 2 };

function badField(field, why) {
  return new LucentError('invalid', `upload frame: ${field} ${why}`, { pointer: `/${field}` });
}

function finiteIn(f, name, lo, hi, openLo = false) {
  const v = f[name];
  if (typeof v !== 'number' || !Number.isFinite(v) || (openLo ? v <= lo : v < lo) || v > hi)
    throw badField(name, `must be a number in ${openLo ? '(' : '['}${lo}, ${hi}]`);
  return v;
}

async function deflateBytes(raw) {
  const zlib = await nodeZlib();
  if (zlib) {
    const out = zlib.deflateSync(raw);
    return new Uint8Array(out.buffer, out.byteOffset, out.length);
  }
  const cs = new CompressionStream('deflate');
  const writer = cs.writable.getWriter();
  writer.write(raw).catch(() => {});
  writer.close().catch(() => {});
  return new Uint8Array(await new Response(cs.readable).arrayBuffer());
}

// Raw little-endian bytes of a plane.
function planeBytes(arr) {
  if (arr instanceof Uint8Array) return arr;
  if (LITTLE_ENDIAN) return new Uint8Array(arr.buffer, arr.byteOffset, arr.byteLength);
  const out = new Uint8Array(arr.length * 2), dv = new DataView(out.buffer);
  for (let i = 0; i < arr.length; i++) dv.setUint16(2 * i, arr[i], true);
  return out;
}

function checkUploadFields(f) {
  if (!f || typeof f !== 'object') throw badField('frame', 'is an object');
  if (!Number.isInteger(f.sequence) || f.sequence < 1 || f.sequence > 0xffffffff) throw badField('sequence', 'must be an integer in [1, 2^32)');
  if (!Number.isSafeInteger(f.captureUs) || f.captureUs < 0) throw badField('captureUs', 'must be an integer >= 0');
  for (const k of ['width', 'height'])
    if (!Number.isInteger(f[k]) || f[k] < 8 || f[k] > 1024) throw badField(k, 'must be an integer in [8, 1024]');
  const n = f.width * f.height;
  if (n > 1048576) throw badField('width', 'times height is over 1048576');
  const de = DEPTH_ENCODINGS[f.depthEncoding], ce = COLOR_ENCODINGS[f.colorEncoding];
  if (!de) throw badField('depthEncoding', "must be 'u16mm' or 'f16m'");
  if (!ce) throw badField('colorEncoding', "must be 'rgb8_srgb' or 'rgb16f_linear'");
  if (!(f.depth instanceof Uint16Array) || f.depth.length !== n) throw badField('depth', `must be a Uint16Array of width*height = ${n}`);
  const CT = ce === 1 ? Uint8Array : Uint16Array;
  if (!(f.color instanceof CT) || f.color.length !== 3 * n)
    throw badField('color', `must be a ${CT.name} of 3*width*height = ${3 * n}`);
  if (f.confidence != null && (!(f.confidence instanceof Uint8Array) || f.confidence.length !== n))
    throw badField('confidence', `must be a Uint8Array of width*height = ${n}`);
  finiteIn(f, 'fx', 0, 1e5, true);
  finiteIn(f, 'fy', 0, 1e5, true);
  finiteIn(f, 'cx', -f.width, 2 * f.width);
  finiteIn(f, 'cy', -f.height, 2 * f.height);
  finiteIn(f, 'exposure', 0, 1e7, true);
  const t = f.translation, r = f.rotation;
  if (!Array.isArray(t) && !ArrayBuffer.isView(t)) throw badField('translation', 'must be 3 numbers');
  if (t.length !== 3 || ![...t].every((v) => Number.isFinite(v) && Math.abs(v) <= 1e6)) throw badField('translation', 'must be 3 numbers with |t| <= 1e6');
  if ((!Array.isArray(r) && !ArrayBuffer.isView(r)) || r.length !== 4 || ![...r].every(Number.isFinite)) throw badField('rotation', 'must be 4 numbers (x, y, z, w)');
  const norm = Math.hypot(...r);
  if (norm < 0.9 || norm > 1.1) throw badField('rotation', `norm ${norm} is not in [0.9, 1.1]`);
  return { de, ce };
}

/**
 * Encodes one RGB-D upload frame exactly per PROTOCOL.md §8.4: the 128-byte little-endian
 * header (reserved bytes 0, CRC-32 of header bytes 0..123 and every plane byte at 124), then
 * depth, confidence (when given), colour. `compress: true` deflates each plane (zlib, RFC
 * 1950). Throws LucentError `invalid` naming the field (pointer `/field`).
 * @param {UploadFrameInput} f
 * @returns {Promise<Uint8Array>}
 */
export async function encodeUploadFrame(f) {
  const { de, ce } = checkUploadFields(f);
  const raw = [planeBytes(f.depth), f.confidence != null ? f.confidence : null, planeBytes(f.color)];
  const planes = [];
  for (const p of raw) planes.push(p === null ? null : f.compress ? await deflateBytes(p) : p);
  const sizes = planes.map((p) => (p ? p.length : 0));
  const out = new Uint8Array(UPLOAD_HEADER_SIZE + sizes[0] + sizes[1] + sizes[2]);
  const dv = new DataView(out.buffer);
  dv.setUint32(0, UPLOAD_MAGIC, true);
  dv.setUint16(4, 1, true);
  out[6] = 1;
  out[7] = planes[1] ? 1 : 0;
  dv.setUint16(8, UPLOAD_HEADER_SIZE, true);
  dv.setUint32(12, f.sequence, true);
  dv.setUint32(16, f.captureUs % TWO_32, true);
  dv.setUint32(20, Math.floor(f.captureUs / TWO_32), true);
  dv.setUint16(24, f.width, true);
  dv.setUint16(26, f.height, true);
  out[28] = de;
  out[29] = ce;
  const z = f.compress ? 1 : 0;
  out[30] = z;
  out[31] = planes[1] ? z : 0;
  out[32] = z;
  [f.fx, f.fy, f.cx, f.cy, ...f.translation, ...f.rotation, f.exposure].forEach((v, i) => dv.setFloat32(36 + 4 * i, v, true));
  dv.setUint32(84, sizes[0], true);
  dv.setUint32(88, sizes[1], true);
  dv.setUint32(92, sizes[2], true);
  let at = UPLOAD_HEADER_SIZE;
  for (const p of planes) {
    if (!p) continue;
    out.set(p, at);
    at += p.length;
  }
  dv.setUint32(UPLOAD_CRC_OFFSET, crc32(out.subarray(UPLOAD_HEADER_SIZE), crc32(out.subarray(0, UPLOAD_CRC_OFFSET))), true);
  return out;
}

/**
 * Reads an upload frame's header (PROTOCOL.md §8.4) without checking it beyond its length:
 * for tests and tools. Field names as encodeUploadFrame's input, plus the plane sizes.
 * @param {Uint8Array} bytes
 * @returns {object}
 */
export function decodeUploadHeader(bytes) {
  const b = toBytes(bytes);
  if (b.length < UPLOAD_HEADER_SIZE) throw new LucentError('invalid', 'shorter than the 128-byte upload header', { pointer: '/frame/length' });
  const dv = new DataView(b.buffer, b.byteOffset, b.byteLength), f32 = (i) => dv.getFloat32(36 + 4 * i, true);
  return {
    magic: dv.getUint32(0, true), version: dv.getUint16(4, true), kind: b[6], flags: b[7], headerSize: dv.getUint16(8, true),
    sequence: dv.getUint32(12, true), captureUs: dv.getUint32(20, true) * TWO_32 + dv.getUint32(16, true),
    width: dv.getUint16(24, true), height: dv.getUint16(26, true), depthEncodingId: b[28], colorEncodingId: b[29],
    depthEncoding: b[28] === 1 ? 'u16mm' : b[28] === 2 ? 'f16m' : null,
    colorEncoding: b[29] === 1 ? 'rgb8_srgb' : b[29] === 2 ? 'rgb16f_linear' : null,
    compression: [b[30], b[31], b[32]], fx: f32(0), fy: f32(1), cx: f32(2), cy: f32(3),
    translation: [f32(4), f32(5), f32(6)], rotation: [f32(7), f32(8), f32(9), f32(10)], exposure: f32(11),
    planeBytes: [dv.getUint32(84, true), dv.getUint32(88, true), dv.getUint32(92, true)], crc: dv.getUint32(124, true),
  };
}
