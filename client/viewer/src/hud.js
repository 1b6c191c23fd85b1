// The HUD: connection and role, the server's revision and the one shown, the refinement pass
// of the lightmap frame on screen, update->frame latency, frames/s and bytes/s per stream,
// and a live list of the changes made by other clients.
const WINDOW_MS = 2000;
const MAX_CHANGED = 8;

const $ = (id) => document.getElementById(id);

export class Hud {
  constructor() {
    this.streams = new Map(); // name -> [{t, bytes}]
    this.lastDraw = 0;
    setInterval(() => this.drawStreams(), 500);
  }

  connection(state, role) {
    const el = $('hud-conn');
    el.textContent = state;
    el.className = state;
    if (role !== undefined) $('hud-role').textContent = role ? `· ${role}` : '';
  }

  revision(server, shown) {
    $('hud-revision').textContent = String(server);
    if (shown !== undefined && shown !== null) $('hud-shown').textContent = String(shown);
  }

  pass(pass, converged) {
    $('hud-pass').textContent = `${pass}${converged ? ' (converged)' : ''}`;
  }

  latency(ms, what) {
    $('hud-latency').textContent = `${ms.toFixed(1)} ms (${what})`;
  }

  frame(stream, bytes) {
    const now = performance.now();
    if (!this.streams.has(stream)) this.streams.set(stream, []);
    const list = this.streams.get(stream);
    list.push({ t: now, bytes });
    while (list.length && now - list[0].t > WINDOW_MS) list.shift();
  }

  drawStreams() {
    const now = performance.now();
    const lines = [];
    for (const [name, list] of this.streams) {
      while (list.length && now - list[0].t > WINDOW_MS) list.shift();
      const fps = (list.length * 1000) / WINDOW_MS;
      const bps = (list.reduce((s, f) => s + f.bytes, 0) * 1000) / WINDOW_MS;
      lines.push(`${name.padEnd(8)} ${fps.toFixed(1).padStart(5)} f/s ${fmtBytes(bps).padStart(9)}/s`);
    }
    $('hud-streams').textContent = lines.join('\n');
  }

  changed(msg) {
    const ul = $('hud-changed');
    const li = document.createElement('li');
    const ids = (msg.ids || []).slice(0, 3).join(', ');
    li.textContent = `r${msg.revision} ${msg.by || '?'}: ${(msg.ops || []).join(', ')}${ids ? ` (${ids})` : ''}`;
    ul.insertBefore(li, ul.firstChild);
    while (ul.children.length > MAX_CHANGED) ul.removeChild(ul.lastChild);
  }
}

function fmtBytes(b) {
  if (b >= 1e6) return `${(b / 1e6).toFixed(2)} MB`;
  if (b >= 1e3) return `${(b / 1e3).toFixed(1)} kB`;
  return `${b.toFixed(0)} B`;
}

/** A message that stays on screen (edits refused, the connection lost). */
export function toast(text, ms = 6000) {
  const el = $('toast');
  el.textContent = text;
  el.classList.remove('hidden');
  clearTimeout(toast.timer);
  if (ms) toast.timer = setTimeout(() => el.classList.add('hidden'), ms);
}

export function banner(text) {
  const el = $('banner');
  el.textContent = text;
  el.classList.toggle('hidden', !text);
}
