// Types of lucent.js, the JavaScript client of lucent/1 (protocol/PROTOCOL.md).

/** Subprotocol offered in the WebSocket handshake (PROTOCOL.md §1.1). */
export declare const PROTOCOL: 'lucent.v1';

export type StreamName = 'lightmap' | 'shgrid' | 'objects' | 'mr.vpl';
export type Encoding = 'rgb9e5' | 'rgba16f' | 'f32';
export type DeltaMode = 'tiles' | 'residual';
export type Role = 'viewer' | 'controller';
export type Vec3 = [number, number, number];
export type RGB = [number, number, number];

/**
 * An error of the protocol or of this library: the server's stable code (PROTOCOL.md §5.2)
 * for refused requests, or the library's own: 'disconnected', 'timeout', 'connect_failed',
 * 'bad_frame', 'resync', 'too_large', 'bad_json', 'invalid'.
 */
export declare class LucentError extends Error {
  constructor(code: string, message: string,
              extra?: { pointer?: string; id?: string | number; stream?: StreamName; reply?: ErrorMessage });
  readonly name: 'LucentError';
  code: string;
  /** RFC 6901 pointer into the offending request ('' = the whole message). */
  pointer?: string;
  /** The request's id. */
  id?: string | number;
  /** The data stream a frame error concerns. */
  stream?: StreamName;
  /** The server's error message as received. */
  reply?: ErrorMessage;
}

/** A data frame's header (PROTOCOL.md §6.1), as parsed. */
export interface FrameHeader {
  version: number;
  streamId: number;
  stream: StreamName | null;
  encodingId: number;
  encoding: Encoding | null;
  /** The raw flags word. */
  flags: number;
  keyframe: boolean;
  delta: boolean;
  residual: boolean;
  /** Flags bit 3 (new): the idle refinement passes of this revision have finished. */
  converged: boolean;
  /** Flags bits 8–15 (new): the refinement pass of this frame, 0 = the revision's first solution. */
  pass: number;
  tileCount: number;
  revision: number;
  sequence: number;
  /** Server clock when the frame was built, µs since the Unix epoch. */
  timestamp_us: number;
  width: number;
  height: number;
  depth: number;
  tileSize: number;
  payloadLength: number;
  crc: number;
  byteLength: number;
  /** Whether the client applied the frame (set once it was handled). */
  applied: boolean;
  /** Lightmap deltas: the bytes the tiles' texels take (for residuals: the inflated size). */
  deltaBytes?: number;
}

interface CopyMeta {
  revision: number;
  sequence: number;
  pass: number;
  converged: boolean;
  timestamp_us: number;
}

/** The client's lightmap copy: the texels encoded as received (residual deltas add to them). */
export interface LightmapCopy extends CopyMeta {
  width: number;
  height: number;
  /** Tile size of delta frames, texels. */
  tile: number;
  encoding: Encoding;
  /** rgb9e5: one word per texel; rgba16f: 4 halves per texel (A = 1); f32: 3 floats per texel. Row 0 = top. */
  data: Uint32Array | Uint16Array | Float32Array;
  /** The tiles the last delta replaced; null after a keyframe. */
  tiles: Uint32Array | null;
}

/** The SH grid: dims x·y·z samples, x fastest, 27 values each (9 coefficients × RGB, §2.3). */
export interface ShGridCopy extends CopyMeta {
  dims: Vec3;
  origin: Vec3;
  cell: number;
  data: Float32Array;
}

/** Irradiance SH (27 values) at each object's position, by object id. */
export interface ObjectsCopy extends CopyMeta {
  /** Ids in the frame's order (sorted). */
  ids: string[];
  byId: Map<string, Float32Array>;
}

export interface Welcome {
  type: 'welcome';
  id?: string | number;
  server: string;
  protocol: 'lucent/1';
  role: Role;
  revision: number;
  scene: {
    lightmap: { width: number; height: number; tile: number; quantity: 'irradiance' };
    grid: { origin: Vec3; cell: number; dims: Vec3; quantity: 'irradiance_sh'; coefficients: number };
    bands: number;
    assets: string[];
    materials: string[];
    /** New: identifies the bake's content. */
    bake_id?: string;
    /** New: HTTP path (same host and port) of the scene's binary glTF. */
    geometry?: string;
    /** New: per asset name, the HTTP path of its binary glTF. */
    asset_geometry?: Record<string, string>;
    [key: string]: unknown;
  };
  limits: { max_message: number; max_lights: number; max_objects: number; max_batch: number; rate: number; [key: string]: unknown };
  [key: string]: unknown;
}

export interface OkMessage { type: 'ok'; id?: string | number; revision: number }
export interface PongMessage { type: 'pong'; id?: string | number; t: number; server_time_us: number }
export interface ErrorMessage { type: 'error'; id?: string | number; code: string; message: string; pointer?: string }
export interface ChangedMessage { type: 'changed'; revision: number; by: string; ops: string[]; ids: string[] }
export interface StateMessage {
  type: 'state';
  id?: string | number;
  revision: number;
  lights: Array<Record<string, unknown>>;
  objects: Array<Record<string, unknown>>;
  materials: Array<{ name: string; emission: RGB }>;
  environment: Record<string, unknown>;
  settings: Record<string, unknown>;
}
export type Reply = OkMessage | StateMessage | PongMessage | Welcome;

/** A client → server message (PROTOCOL.md §4); `id` is assigned when absent. */
export interface Request {
  type: string;
  id?: string | number;
  [key: string]: unknown;
}

/** A WebSocket constructor: the browser's, or e.g. the `ws` package's default export in Node. */
export type WebSocketConstructor = new (url: string, protocols?: string | string[]) => any;

export interface LucentClientOptions {
  /** Access token ('' = none). */
  token?: string;
  /** Client name shown in `changed` (default 'lucent.js'). */
  client?: string;
  /** Default: globalThis.WebSocket. */
  WebSocket?: WebSocketConstructor;
  /** Reconnect after a connection lost after its welcome (default false, as liblucent-client). */
  reconnect?: boolean;
  /** Exponential back-off with ±20 % jitter: first delay initialMs (250), doubling up to maxMs (8000). */
  backoff?: { initialMs?: number; maxMs?: number };
  /** Consecutive failed reconnect attempts before giving up; 0 = forever (default). */
  maxRetries?: number;
  /** Connect (welcome) and request timeout, ms (default 5000). */
  timeout?: number;
  /** Largest server text while a state.get is in flight (default 16 MiB; otherwise welcome.limits.max_message). */
  maxStateBytes?: number;
  /** Capabilities asked for in hello (§8.1, 0..8 strings of 1..32), e.g. ['mr']. */
  capabilities?: string[];
}

/** mr.begin's session (PROTOCOL.md §8.2). */
export interface MrSession {
  objects: string[];
  width: number;
  height: number;
  depth: 'u16mm' | 'f16m';
  color: 'rgb8_srgb' | 'rgb16f_linear';
  max_rate?: number;
  glossy?: boolean;
  specular_exponent?: number;
  min_confidence?: number;
  smoothing?: number;
  light?: 'replace' | 'add';
}

/** ok.mr: the server's limits for the session (§8.2). */
export interface MrGrant { session: number; max_frame: number; max_rate: number; max_lights: number; points: number }

/** mr.ack (§8.5). */
export interface MrAck { type: 'mr.ack'; seq: number; capture_us: number; status: 'processed' | 'replaced'; lights: number; ms: number }

/** encodeUploadFrame's input (§8.4). */
export interface UploadFrameInput {
  /** ≥ 1, strictly increasing within the session. */
  sequence: number;
  /** Capture time, µs (the client's clock). */
  captureUs: number;
  width: number;
  height: number;
  depthEncoding: 'u16mm' | 'f16m';
  /** width·height: millimetres (u16mm) or binary16 metres (f16m). */
  depth: Uint16Array;
  colorEncoding: 'rgb8_srgb' | 'rgb16f_linear';
  /** 3·width·height: sRGB bytes, or binary16 linear. */
  color: Uint8Array | Uint16Array;
  /** width·height, 0..255. */
  confidence?: Uint8Array | null;
  fx: number; fy: number; cx: number; cy: number;
  translation: ArrayLike<number>;
  /** Unit quaternion x, y, z, w. */
  rotation: ArrayLike<number>;
  exposure: number;
  /** zlib every plane (default false). */
  compress?: boolean;
}

/** An upload frame's header as decodeUploadHeader reads it. */
export interface UploadHeader {
  magic: number; version: number; kind: number; flags: number; headerSize: number; sequence: number; captureUs: number;
  width: number; height: number; depthEncodingId: number; colorEncodingId: number;
  depthEncoding: 'u16mm' | 'f16m' | null; colorEncoding: 'rgb8_srgb' | 'rgb16f_linear' | null;
  /** Depth, confidence, colour: 0 none, 1 zlib. */
  compression: [number, number, number];
  fx: number; fy: number; cx: number; cy: number; translation: Vec3; rotation: [number, number, number, number]; exposure: number;
  planeBytes: [number, number, number];
  crc: number;
}

/** One session object's VPLs (§8.7): count records of 12 values I_d, l_d, I_s, l_s. */
export interface MrVplObject { id: string; count: number; records: Float32Array }

/** The mr.vpl copy. */
export interface MrVplCopy {
  objects: MrVplObject[];
  byId: Map<string, MrVplObject>;
  encoding: 'f32' | 'rgba16f';
  /** Points over all objects (the header's height). */
  points: number;
  revision: number;
  sequence: number;
  timestamp_us: number;
}

export interface SubscribeOptions {
  /** Default: the server's (lightmap rgb9e5, SH streams f32). */
  encoding?: Encoding;
  /** Lightmap only (default tiles). */
  delta?: DeltaMode;
  /** Frames per second, 0.1..120. */
  max_rate?: number;
  /** Reply timeout, ms. */
  timeout?: number;
}

export interface CloseInfo { code?: number; reason: string; reconnecting: boolean }
export interface ReconnectInfo { attempt: number; delayMs: number; reason: string }

export interface ClientStats {
  frames: number;
  keyframes: number;
  deltas: number;
  badFrames: number;
  resyncs: number;
  reconnects: number;
  bytes: number;
}

export interface LucentEvents {
  /** The socket opened; hello was sent. */
  open: () => void;
  /** A welcome (also after each reconnect, before the resubscriptions' frames). */
  welcome: (msg: Welcome) => void;
  /** A connection that had its welcome closed (or close() was called). */
  close: (info: CloseInfo) => void;
  /** Waiting delayMs before reconnect attempt `attempt`. */
  reconnecting: (info: ReconnectInfo) => void;
  changed: (msg: ChangedMessage) => void;
  /** A state message (the reply to state.get). */
  state: (msg: StateMessage) => void;
  /** Bad or inapplicable frames (then a snapshot is requested), unsolicited server errors, … */
  error: (err: LucentError) => void;
  lightmap: (copy: LightmapCopy, header: FrameHeader) => void;
  shgrid: (copy: ShGridCopy, header: FrameHeader) => void;
  objects: (copy: ObjectsCopy, header: FrameHeader) => void;
  'mr.vpl': (copy: MrVplCopy, header: FrameHeader) => void;
  /** Every mr.ack (also those whose send already rejected or timed out). */
  'mr.ack': (ack: MrAck) => void;
  /** Every frame whose header parsed, after it was handled (header.applied), with its bytes. */
  frame: (header: FrameHeader, bytes: Uint8Array) => void;
}

export declare class LucentClient {
  constructor(url: string, options?: LucentClientOptions);
  readonly url: string;
  /** The current connection's welcome (null before the first). */
  welcome: Welcome | null;
  role: Role | null;
  /** The latest revision seen in welcome, ok, changed, state and frames. */
  revision: number;
  lightmap: LightmapCopy | null;
  shgrid: ShGridCopy | null;
  objects: ObjectsCopy | null;
  /** mr.vpl copy (null until its first frame). */
  mrVpl: MrVplCopy | null;
  /** The capabilities the welcome granted ([] when none). */
  capabilities: string[];
  /** The welcome's version ('1.0' when it has none; null before the first welcome). */
  protocolVersion: string | null;
  stats: ClientStats;
  readonly connected: boolean;
  on<K extends keyof LucentEvents>(event: K, fn: LucentEvents[K]): this;
  off<K extends keyof LucentEvents>(event: K, fn: LucentEvents[K]): this;
  /** Resolves with the welcome; rejects with LucentError (the server's code, e.g. 'unauthorized', or 'connect_failed', 'timeout'). */
  connect(): Promise<Welcome>;
  /** Resolves with the reply matched by id; rejects with LucentError {code, message, pointer, id}. */
  request<T extends Reply = Reply>(msg: Request, options?: { timeout?: number }): Promise<T>;
  subscribe(stream: StreamName, options?: SubscribeOptions): Promise<OkMessage>;
  unsubscribe(stream: StreamName): Promise<OkMessage>;
  snapshot(): Promise<OkMessage>;
  state(): Promise<StateMessage>;
  ping(t?: number): Promise<PongMessage & { rtt_ms: number }>;
  /** Applies a frame as if received (tests, replays); resolves whether it was applied. */
  handleFrame(data: ArrayBuffer | ArrayBufferView): Promise<boolean>;
  close(): void;
  /** Opens (replaces) the MR session; resolves ok.mr; rejects LucentError (mr_not_enabled, unknown_id, invalid, out_of_range). */
  mrBegin(session: MrSession, options?: { timeout?: number }): Promise<MrGrant>;
  mrEnd(options?: { timeout?: number }): Promise<OkMessage>;
  /** Sends an upload frame (at most 2 unacknowledged; more wait); resolves its mr.ack; an upload error rejects the oldest. */
  sendUploadFrame(bytes: Uint8Array, options?: { timeout?: number }): Promise<MrAck>;
}

/** CRC-32 (IEEE, as zlib), continuing from `crc`. */
export declare function crc32(bytes: Uint8Array, crc?: number): number;
/** GL RGB9_E5 texel → linear RGB. */
export declare function decodeRGB9E5(word: number): RGB;
/** binary16 bit pattern → number. */
export declare function halfToFloat(h: number): number;
/** A lightmap copy → W·H·3 float32 RGB irradiance (W/m²); `out` is reused when it fits. */
export declare function lightmapToFloat32(copy: Pick<LightmapCopy, 'width' | 'height' | 'encoding' | 'data'>,
                                          out?: Float32Array): Float32Array;
/** E(n) = Σ c_i y_i(n) of 27 cosine-convolved irradiance SH values (§2.3), clamped at 0. */
export declare function shIrradiance(coeffs: ArrayLike<number>, normal: ArrayLike<number>): RGB;
/** 27 irradiance SH values → 9 RGB radiance coefficients for three.js SphericalHarmonics3 / LightProbe.sh. */
export declare function shToThreeCoefficients(coeffs: ArrayLike<number>): RGB[];
/** Checks and parses a frame; throws LucentError 'bad_frame'. */
export declare function parseFrame(data: ArrayBuffer | ArrayBufferView): { header: FrameHeader; tiles: Uint32Array; payload: Uint8Array };
/** Inflates a zlib stream to exactly `expected` bytes or rejects. */
export declare function inflateExact(data: Uint8Array, expected: number, options?: { decompressionStream?: boolean }): Promise<Uint8Array>;
/** Encodes an RGB-D upload frame exactly per §8.4; rejects LucentError 'invalid' with pointer '/field'. */
export declare function encodeUploadFrame(frame: UploadFrameInput): Promise<Uint8Array>;
/** Reads an upload frame's 128-byte header (no checks beyond its length). */
export declare function decodeUploadHeader(bytes: ArrayBuffer | ArrayBufferView): UploadHeader;
