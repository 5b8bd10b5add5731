// svetlo's live preview page: receives the render's state (JSON) and images (half floats)
// over one WebSocket, shows them tone-mapped, and sends back stop / restart / layer commands.
'use strict';

const token = new URLSearchParams(location.search).get('token') || '';
const $ = (id) => document.getElementById(id);
const COLOURS = ['#f0a030', '#4fa3e0', '#6cc36c', '#c07ee0'];

// What the page holds; `window.svetlo` lets tests (and curious users) look inside.
const app = {
  hello: null,
  status: null,
  frames: [],        // per slot: {w, h, spp, run, layer, data: Float32Array (RGB)}
  framesReceived: 0,
  drawn: 0,
  view: { scale: 1, x: 0, y: 0, fitted: false },
  split: 0.5,
  socket: null,
};
window.svetlo = app;

// Half float -> float, by table: a frame is decoded with one lookup per value.
const HALF = new Float32Array(65536);
for (let h = 0; h < 65536; h++) {
  const s = h & 0x8000 ? -1 : 1, e = (h >> 10) & 0x1f, m = h & 0x3ff;
  HALF[h] = e === 0 ? s * m * 2 ** -24 : e === 31 ? (m ? NaN : s * Infinity) : s * (1 + m / 1024) * 2 ** (e - 15);
}

function decodeFrame(buf) {
  const dv = new DataView(buf);
  const magic = String.fromCharCode(dv.getUint8(0), dv.getUint8(1), dv.getUint8(2), dv.getUint8(3));
  if (magic !== 'SVF1') return;
  const slot = dv.getUint8(4), layer = dv.getUint8(5);
  const w = dv.getUint32(8, true), h = dv.getUint32(12, true), spp = dv.getUint32(16, true), run = dv.getUint32(20, true);
  const halves = new Uint16Array(buf, 24, w * h * 3);
  const data = new Float32Array(w * h * 3);
  for (let i = 0; i < data.length; i++) data[i] = HALF[halves[i]];
  app.frames[slot] = { w, h, spp, run, layer, data };
  app.framesReceived++;
  scheduleDraw();
}

// ---- connection ----
function connect() {
  const ws = new WebSocket(`${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/ws?token=${token}`);
  ws.binaryType = 'arraybuffer';
  app.socket = ws;
  ws.onopen = () => { $('connection').textContent = 'live'; };
  ws.onclose = () => {
    const ended = app.status && app.status.shutdown;
    $('connection').textContent = ended ? 'render ended: the server has closed' : 'disconnected';
    $('stop').disabled = true;
    $('render-settings').disabled = true;
  };
  ws.onmessage = (ev) => {
    if (typeof ev.data !== 'string') return decodeFrame(ev.data);
    const msg = JSON.parse(ev.data);
    if (msg.type === 'hello') onHello(msg);
    else if (msg.type === 'status') onStatus(msg);
  };
}

function send(text) {
  if (app.socket && app.socket.readyState === WebSocket.OPEN) app.socket.send(text);
}

function onHello(h) {
  app.hello = h;
  $('scene').textContent = h.scene;
  for (const sel of [$('method-a'), $('method-b')]) {
    for (const m of h.methods) {
      const o = document.createElement('option');
      o.value = m.name; o.textContent = m.name; o.title = m.summary;
      sel.appendChild(o);
    }
  }
  $('layer').replaceChildren(...h.layers.map((l) => { const o = document.createElement('option'); o.value = o.textContent = l; return o; }));
  $('render-settings').disabled = h.mode !== 'serve';
  if (h.mode !== 'serve') $('render-settings').title = "started by 'svetlo render': use 'svetlo serve' to change the method from here";
  $('plot-note').textContent = h.reference ? 'relMSE against the reference image' : "relMSE estimated from each method's own per-pixel variance";
}

let configShown = -1;
function onStatus(s) {
  const previous = app.status;
  app.status = s;
  if (configShown !== s.run) {
    // A new run: show its settings in the controls, forget the old images.
    configShown = s.run;
    $('method-a').value = s.config.methods[0] || '';
    $('method-b').value = s.config.methods[1] || '';
    $('spp').value = s.config.spp;
    $('depth').value = s.config.max_depth;
    app.frames = app.frames.filter((f) => f && f.run === s.run);
    buildViews();
  } else if (!previous || previous.slots.length !== s.slots.length) {
    buildViews();
  }
  $('message').textContent = s.message;
  $('stop').disabled = !s.running;
  showProgress(s);
  drawPlot(s);
  showResults(s);
  scheduleDraw();
}

// ---- views: one per slot side by side, or two in one with a split ----
function layout() { return document.querySelector('input[name=layout]:checked').value; }

function buildViews() {
  const n = app.status ? app.status.slots.length : 1;
  const box = $('views');
  box.replaceChildren();
  box.className = layout();
  const names = app.status ? app.status.slots.map((s) => s.method) : [];
  const split = layout() === 'split' && n >= 2;
  const views = split ? [[0, 1]] : names.map((_, i) => [i]);
  for (const slots of views) {
    const v = document.createElement('div');
    v.className = 'view';
    slots.forEach((slot, k) => {
      const c = document.createElement('canvas');
      c.dataset.slot = slot;
      c.style.zIndex = 1 + k;
      v.appendChild(c);
      const l = document.createElement('div');
      l.className = 'label' + (k === 1 ? ' right' : '');
      l.style.color = COLOURS[slot % COLOURS.length];
      l.textContent = names[slot] || '';
      v.appendChild(l);
    });
    if (split) {
      const d = document.createElement('div');
      d.id = 'divider';
      v.appendChild(d);
      dragDivider(d, v);
    }
    attachPanZoom(v);
    box.appendChild(v);
  }
  app.view.fitted = false;
  scheduleDraw();
}

function dragDivider(d, view) {
  d.addEventListener('pointerdown', (e) => {
    e.stopPropagation();
    d.setPointerCapture(e.pointerId);
    const move = (ev) => {
      const r = view.getBoundingClientRect();
      app.split = Math.min(1, Math.max(0, (ev.clientX - r.left) / r.width));
      placeTransforms();
    };
    d.addEventListener('pointermove', move);
    d.addEventListener('pointerup', () => d.removeEventListener('pointermove', move), { once: true });
  });
}

function attachPanZoom(v) {
  v.addEventListener('wheel', (e) => {
    e.preventDefault();
    const r = v.getBoundingClientRect();
    const px = e.clientX - r.left, py = e.clientY - r.top;
    const f = Math.exp(-e.deltaY * 0.0015);
    const s = Math.min(64, Math.max(0.05, app.view.scale * f));
    app.view.x = px - (px - app.view.x) * (s / app.view.scale);
    app.view.y = py - (py - app.view.y) * (s / app.view.scale);
    app.view.scale = s;
    placeTransforms();
  }, { passive: false });
  v.addEventListener('pointerdown', (e) => {
    v.setPointerCapture(e.pointerId);
    const start = { x: e.clientX, y: e.clientY, vx: app.view.x, vy: app.view.y };
    const move = (ev) => { app.view.x = start.vx + ev.clientX - start.x; app.view.y = start.vy + ev.clientY - start.y; placeTransforms(); };
    v.addEventListener('pointermove', move);
    v.addEventListener('pointerup', () => v.removeEventListener('pointermove', move), { once: true });
  });
  v.addEventListener('mousemove', (e) => showPixel(e, v));
  v.addEventListener('dblclick', () => { app.view.fitted = false; fit(); });
}

function fit() {
  const f = app.frames.find((x) => x);
  const v = document.querySelector('.view');
  if (!f || !v) return;
  const r = v.getBoundingClientRect();
  const s = Math.min(r.width / f.w, r.height / f.h);
  app.view = { scale: s, x: (r.width - f.w * s) / 2, y: (r.height - f.h * s) / 2, fitted: true };
  placeTransforms();
}

function placeTransforms() {
  for (const c of document.querySelectorAll('.view canvas')) {
    c.style.transform = `translate(${app.view.x}px, ${app.view.y}px) scale(${app.view.scale})`;
  }
  const split = document.getElementById('divider');
  if (split) {
    const v = split.parentElement, w = v.getBoundingClientRect().width;
    split.style.left = `${app.split * w}px`;
    // The second method shows right of the divider: clip it in its own (scaled) coordinates.
    const top = v.querySelector('canvas[data-slot="1"]');
    if (top) {
      const cut = (app.split * w - app.view.x) / app.view.scale;
      top.style.clipPath = `inset(0 0 0 ${Math.max(0, cut)}px)`;
    }
  }
}

function showPixel(e, v) {
  const r = v.getBoundingClientRect();
  const x = Math.floor((e.clientX - r.left - app.view.x) / app.view.scale);
  const y = Math.floor((e.clientY - r.top - app.view.y) / app.view.scale);
  const lines = [];
  for (const c of v.querySelectorAll('canvas')) {
    const slot = +c.dataset.slot, f = app.frames[slot];
    if (!f || x < 0 || y < 0 || x >= f.w || y >= f.h) continue;
    const i = (y * f.w + x) * 3, [R, G, B] = [f.data[i], f.data[i + 1], f.data[i + 2]];
    const L = 0.2126 * R + 0.7152 * G + 0.0722 * B;
    const name = app.status ? app.status.slots[slot].method : slot;
    lines.push(`${name.padEnd(10)} RGB ${fmt(R)} ${fmt(G)} ${fmt(B)}  L ${fmt(L)}`);
  }
  $('pixel').textContent = `pixel (${x}, ${y})\n` + (lines.join('\n') || 'outside the image');
}

const fmt = (v) => (Math.abs(v) >= 1e4 || (v !== 0 && Math.abs(v) < 1e-3) ? v.toExponential(3) : v.toFixed(4)).padStart(10);

// ---- drawing ----
let drawQueued = false;
function scheduleDraw() {
  if (drawQueued) return;
  drawQueued = true;
  requestAnimationFrame(() => { drawQueued = false; draw(); });
}

// Viridis, sampled: dark for little light, yellow for much.
const MAP = [[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]];
function colormap(t) {
  t = Math.min(1, Math.max(0, t)) * (MAP.length - 1);
  const i = Math.min(MAP.length - 2, Math.floor(t)), u = t - i;
  return MAP[i].map((a, k) => a + (MAP[i + 1][k] - a) * u);
}

// The false-colour range: log10 of luminance from the 1st to the 99th percentile of lit pixels.
function logRange() {
  const ls = [];
  for (const f of app.frames) {
    if (!f) continue;
    const step = Math.max(1, Math.floor(f.w * f.h / 20000));
    for (let p = 0; p < f.w * f.h; p += step) {
      const L = 0.2126 * f.data[3 * p] + 0.7152 * f.data[3 * p + 1] + 0.0722 * f.data[3 * p + 2];
      if (L > 0 && isFinite(L)) ls.push(Math.log10(L));
    }
  }
  if (!ls.length) return [-3, 0];
  ls.sort((a, b) => a - b);
  const lo = ls[Math.floor(ls.length * 0.01)], hi = ls[Math.floor(ls.length * 0.99)];
  return hi - lo < 1e-3 ? [lo - 0.5, hi + 0.5] : [lo, hi];
}

function draw() {
  const exposure = 2 ** +$('exposure').value, invGamma = 1 / +$('gamma').value;
  const falseColour = $('false-colour').checked;
  const range = falseColour ? logRange() : null;
  for (const c of document.querySelectorAll('.view canvas')) {
    const f = app.frames[+c.dataset.slot];
    if (!f) continue;
    if (c.width !== f.w || c.height !== f.h) { c.width = f.w; c.height = f.h; }
    const ctx = c.getContext('2d');
    const img = ctx.createImageData(f.w, f.h), out = img.data, d = f.data;
    for (let p = 0, n = f.w * f.h; p < n; p++) {
      const r = d[3 * p], g = d[3 * p + 1], b = d[3 * p + 2];
      if (falseColour) {
        const L = (0.2126 * r + 0.7152 * g + 0.0722 * b) * exposure;
        const rgb = L > 0 ? colormap((Math.log10(L) - range[0]) / (range[1] - range[0])) : [0, 0, 0];
        out[4 * p] = rgb[0]; out[4 * p + 1] = rgb[1]; out[4 * p + 2] = rgb[2];
      } else {
        out[4 * p] = 255 * Math.max(0, r * exposure) ** invGamma;
        out[4 * p + 1] = 255 * Math.max(0, g * exposure) ** invGamma;
        out[4 * p + 2] = 255 * Math.max(0, b * exposure) ** invGamma;
      }
      out[4 * p + 3] = 255;
    }
    ctx.putImageData(img, 0, 0);
  }
  if (!app.view.fitted && app.frames.some((x) => x)) fit();
  placeTransforms();
  $('legend-box').hidden = !falseColour;
  if (falseColour) drawLegend(range, exposure);
  app.drawn++;
}

function drawLegend(range, exposure) {
  const c = $('legend'), ctx = c.getContext('2d');
  for (let x = 0; x < c.width; x++) {
    const [r, g, b] = colormap(x / (c.width - 1));
    ctx.fillStyle = `rgb(${r},${g},${b})`;
    ctx.fillRect(x, 0, 1, c.height);
  }
  // Labels in the image's own luminance (before exposure).
  const e = Math.log10(exposure);
  $('legend-lo').textContent = `L ${(10 ** (range[0] - e)).toExponential(1)}`;
  $('legend-hi').textContent = `${(10 ** (range[1] - e)).toExponential(1)}`;
}

// ---- progress, plot, table ----
const secs = (t) => (t == null ? '–' : t < 60 ? `${t.toFixed(1)} s` : `${Math.floor(t / 60)} min ${Math.round(t % 60)} s`);

function showProgress(s) {
  $('progress').replaceChildren(...s.slots.map((sl, i) => {
    const d = document.createElement('div');
    d.className = 'slot';
    d.innerHTML = `<div><b style="color:${COLOURS[i % COLOURS.length]}"></b> <span class="muted"></span></div><div class="bar"><div></div></div>`;
    d.querySelector('b').textContent = sl.method;
    d.querySelector('span').textContent = `${sl.state}, ${sl.spp} spp, ${secs(sl.elapsed)}` + (sl.state === 'running' ? `, ETA ${secs(sl.eta)}` : '');
    d.querySelector('.bar > div').style.width = `${(100 * sl.fraction).toFixed(1)}%`;
    return d;
  }));
}

function drawPlot(s) {
  const c = $('plot'), ctx = c.getContext('2d'), W = c.width, H = c.height, m = { l: 52, r: 10, t: 10, b: 30 };
  ctx.clearRect(0, 0, W, H);
  const pts = s.slots.flatMap((sl) => sl.curve).filter((p) => p[0] > 0 && p[1] > 0);
  ctx.fillStyle = '#8d939c'; ctx.strokeStyle = '#3a3f47'; ctx.font = '11px sans-serif';
  if (!pts.length) { ctx.fillText('waiting for the first passes…', m.l, H / 2); return; }
  const lx = pts.map((p) => Math.log10(p[0])), ly = pts.map((p) => Math.log10(p[1]));
  let [x0, x1, y0, y1] = [Math.min(...lx), Math.max(...lx), Math.min(...ly), Math.max(...ly)];
  if (x1 - x0 < 0.3) { x0 -= 0.15; x1 += 0.15; }
  if (y1 - y0 < 0.3) { y0 -= 0.15; y1 += 0.15; }
  const X = (v) => m.l + (Math.log10(v) - x0) / (x1 - x0) * (W - m.l - m.r);
  const Y = (v) => H - m.b - (Math.log10(v) - y0) / (y1 - y0) * (H - m.t - m.b);
  // Decade grid lines, labelled.
  for (let e = Math.ceil(y0); e <= Math.floor(y1); e++) {
    ctx.beginPath(); ctx.moveTo(m.l, Y(10 ** e)); ctx.lineTo(W - m.r, Y(10 ** e)); ctx.stroke();
    ctx.fillText(`1e${e}`, 4, Y(10 ** e) + 4);
  }
  for (let e = Math.ceil(x0); e <= Math.floor(x1); e++) {
    ctx.beginPath(); ctx.moveTo(X(10 ** e), m.t); ctx.lineTo(X(10 ** e), H - m.b); ctx.stroke();
    ctx.fillText(`${10 ** e} s`, X(10 ** e) - 8, H - m.b + 14);
  }
  ctx.fillText('time (s, log)', W / 2 - 30, H - 4);
  ctx.save(); ctx.translate(12, H / 2 + 20); ctx.rotate(-Math.PI / 2); ctx.fillText('relMSE', 0, 0); ctx.restore();
  s.slots.forEach((sl, i) => {
    const c2 = sl.curve.filter((p) => p[0] > 0 && p[1] > 0);
    if (!c2.length) return;
    ctx.strokeStyle = ctx.fillStyle = COLOURS[i % COLOURS.length];
    ctx.lineWidth = 2;
    ctx.beginPath();
    c2.forEach((p, k) => (k ? ctx.lineTo(X(p[0]), Y(p[1])) : ctx.moveTo(X(p[0]), Y(p[1]))));
    ctx.stroke();
    for (const p of c2) ctx.fillRect(X(p[0]) - 1.5, Y(p[1]) - 1.5, 3, 3);
    ctx.fillText(sl.method, W - m.r - 70, m.t + 12 + 14 * i);
    ctx.lineWidth = 1; ctx.strokeStyle = '#3a3f47';
  });
}

function showResults(s) {
  const rows = s.slots.map((sl) => {
    const tr = document.createElement('tr');
    const cells = [sl.method, sl.state, sl.spp, secs(sl.elapsed), sl.relmse == null ? '–' : sl.relmse.toExponential(3),
      sl.samples_per_s ? `${(sl.samples_per_s / 1e6).toFixed(2)} M` : '–', sl.error || sl.written.join(' ')];
    cells.forEach((v, k) => { const td = document.createElement('td'); td.textContent = v; if (k === 6) td.className = 'files'; tr.appendChild(td); });
    return tr;
  });
  $('results').tBodies[0].replaceChildren(...rows);
}

// ---- controls ----
$('stop').onclick = () => send('stop');
$('restart').onclick = () => {
  const methods = [$('method-a').value, $('method-b').value].filter((m) => m);
  send(`restart methods=${methods.join(',')} spp=${Math.max(1, Math.round(+$('spp').value))} depth=${Math.round(+$('depth').value)}`);
};
$('layer').onchange = () => send(`layer ${$('layer').value}`);
$('fit').onclick = () => fit();
for (const r of document.querySelectorAll('input[name=layout]')) r.onchange = buildViews;
for (const id of ['exposure', 'gamma']) {
  $(id).oninput = () => { $(`${id}-value`).textContent = (+$(id).value).toFixed(id === 'gamma' ? 2 : 1); scheduleDraw(); };
}
$('false-colour').onchange = scheduleDraw;
window.addEventListener('resize', () => { app.view.fitted = false; scheduleDraw(); });

buildViews();
connect();
