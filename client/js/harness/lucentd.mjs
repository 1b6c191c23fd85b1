// Test support for client/js/test (kept out of test/ so that `node --test js/test/` does not
// run it as a test file): starts this build's lucentd, waits for events, records frames and
// replays them through liblucent-client (tests/js/replay_frames.c).
import { spawn, execFile } from 'node:child_process';
import { mkdtempSync, rmSync, existsSync, writeFileSync, readFileSync, openSync, closeSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join, resolve, dirname } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
/** The repository root. */
export const SOURCE_DIR = process.env.LUCENT_SOURCE_DIR || resolve(here, '../../..');
/** The build: bin/lucentd, bin/lucentctl, cornell.lcb, tests/replay_frames. */
export const BINARY_DIR = process.env.LUCENT_BINARY_DIR || join(SOURCE_DIR, 'build');
export const LUCENTD = join(BINARY_DIR, 'bin', 'lucentd');
export const LUCENTCTL = join(BINARY_DIR, 'bin', 'lucentctl');
export const CORNELL = join(BINARY_DIR, 'cornell.lcb');
export const REPLAY = join(BINARY_DIR, 'tests', 'replay_frames');
export const TOKENS = { controller: 'js-test-controller', viewer: 'js-test-viewer' };

/** Why the live tests cannot run here (null when they can). */
export function missing() {
  for (const f of [LUCENTD, LUCENTCTL, CORNELL, REPLAY])
    if (!existsSync(f)) return `${f} is missing (set LUCENT_BINARY_DIR to a build with lucentd, lucentctl, cornell_bake and replay_frames)`;
  return null;
}

/** A fresh temporary directory, removed by cleanup(). */
export function tempDir(tag) {
  return mkdtempSync(join(tmpdir(), `lucent-js-${tag}-`));
}

export function cleanup(dir) {
  rmSync(dir, { recursive: true, force: true });
}

/**
 * Starts lucentd on `port` (0: any free port, read from its `lucentd listening port=N` line)
 * with its state in `stateDir`, the build's Cornell bake, the cpu backend and the test tokens
 * (tokens: false for none: every client is then a controller). Also used by tests/viewer.
 * Resolves {proc, port, url, stateDir, log(), stop(signal)}.
 */
export function startLucentd({ stateDir, port = 0, args = [], tokens = true, timeoutMs = 20000 }) {
  const errPath = `${stateDir}.err`;
  const errFd = openSync(errPath, 'a');
  const tokenArgs = tokens ? ['--controller-tokens', TOKENS.controller, '--viewer-tokens', TOKENS.viewer] : [];
  const argv = ['--bake', CORNELL, '--port', String(port), '--state-dir', stateDir, '--backend', 'cpu',
    '--log-level', 'warn', ...tokenArgs, '--threads', '2', '--rate', '10000', ...args];
  const proc = spawn(LUCENTD, argv, { stdio: ['ignore', 'pipe', errFd] });
  closeSync(errFd);
  const log = () => (existsSync(errPath) ? readFileSync(errPath, 'utf8') : '');
  return new Promise((resolveStart, reject) => {
    let out = '';
    const timer = setTimeout(() => {
      proc.kill('SIGKILL');
      reject(new Error(`lucentd did not say its port within ${timeoutMs} ms: ${log().slice(-800)}`));
    }, timeoutMs);
    proc.stdout.on('data', (d) => {
      out += d;
      const m = /^lucentd listening port=(\d+)/m.exec(out);
      if (m && timer) {
        clearTimeout(timer);
        const p = Number(m[1]);
        const exited = new Promise((r) => proc.once('exit', (code, sig) => r(code === null ? sig : code)));
        resolveStart({
          proc, port: p, url: `ws://127.0.0.1:${p}/`, stateDir, log, exited,
          stop: (signal = 'SIGTERM') => {
            if (proc.exitCode === null && proc.signalCode === null) proc.kill(signal);
            return exited;
          },
        });
      }
    });
    proc.once('exit', (code) => {
      clearTimeout(timer);
      reject(new Error(`lucentd exited (${code}) before listening: ${log().slice(-800)}`));
    });
  });
}

/**
 * Resolves with the arguments of the first `event` of `client` for which pred(...args) is
 * true; rejects after timeoutMs naming `what`.
 */
export function waitFor(client, event, pred = () => true, timeoutMs = 10000, what = event) {
  return new Promise((res, rej) => {
    const fn = (...args) => {
      if (!pred(...args)) return;
      clearTimeout(timer);
      client.off(event, fn);
      res(args);
    };
    const timer = setTimeout(() => {
      client.off(event, fn);
      rej(new Error(`timed out after ${timeoutMs} ms waiting for ${what}`));
    }, timeoutMs);
    client.on(event, fn);
  });
}

/** Waits for a converged frame of revision >= rev on `stream` (its copy). */
export function waitConverged(client, stream, rev, timeoutMs = 15000) {
  const c = client[stream];
  if (c && c.revision >= rev && c.converged) return Promise.resolve([c]);
  return waitFor(client, stream, (copy) => copy.revision >= rev && copy.converged, timeoutMs,
    `a converged ${stream} frame of revision ${rev}`);
}

/** Records every frame the client receives (bytes as received, header), in order. */
export function record(client) {
  const frames = [];
  client.on('frame', (header, bytes) => frames.push({ header, bytes: bytes.slice() }));
  return frames;
}

function run(cmd, args) {
  return new Promise((res, rej) => {
    execFile(cmd, args, { maxBuffer: 64 << 20 }, (err, stdout, stderr) => {
      if (err) rej(new Error(`${cmd} ${args.join(' ')}: ${err.message}\n${stderr}`));
      else res(stdout);
    });
  });
}

/**
 * Applies `frames` (Uint8Arrays) with liblucent-client's lc_client_view_apply: resolves
 * {results: one object per frame (rc, stream, sequence, revision, keyframe, residual, pass,
 * converged, values, crc[, ids]), values: {stream: Float32Array of the final copy}}.
 */
export async function replay(frames, dir) {
  const parts = [];
  for (const f of frames) {
    const len = Buffer.alloc(4);
    len.writeUInt32LE(f.length);
    parts.push(len, Buffer.from(f.buffer, f.byteOffset, f.byteLength));
  }
  const input = join(dir, `frames-${Date.now()}-${Math.random().toString(36).slice(2)}.bin`);
  writeFileSync(input, Buffer.concat(parts));
  const prefix = `${input}.out`;
  const stdout = await run(REPLAY, [input, prefix]);
  const results = stdout.trim().split('\n').filter(Boolean).map((l) => JSON.parse(l));
  const values = {};
  for (const s of ['lightmap', 'shgrid', 'objects']) {
    const p = `${prefix}-${s}.f32`;
    if (existsSync(p)) {
      const b = readFileSync(p);
      values[s] = new Float32Array(b.buffer.slice(b.byteOffset, b.byteOffset + b.byteLength));
    }
  }
  return { results, values };
}

/** Runs lucentctl (global options first) and resolves its stdout. */
export function lucentctl(url, token, args) {
  return run(LUCENTCTL, ['--url', url, '--token', token, ...args]);
}

/** Little-endian bytes of a Float32Array, as files and CRCs see them. */
export function floatBytes(f) {
  return new Uint8Array(f.buffer, f.byteOffset, f.byteLength);
}
