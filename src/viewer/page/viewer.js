// splatray view: the page. Plain JavaScript, no build step. It holds the
// camera, sends it (and every other request) as JSON over one WebSocket,
// and draws the frames the server streams back: a binary message of a
// little-endian u32 header length, a JSON header and PNG bytes.
"use strict";

const $ = (id) => document.getElementById(id);
const canvas = $("view");
const ctx = canvas.getContext("2d");

// What the tests and the latency script read (window.viewer).
const V = {
  hello: null,
  cam: null,
  frames: [],       // every frame header, in arrival order
  errors: [],       // every error message
  latencies: [],    // ms from a camera's input to its first frame drawn
  lastFull: null,   // {header, bytes} of the last full-quality image
  lastRefined: null,
  lastShown: null,  // the last non-preview image frame (what "save image" saves)
  sceneText: null,
  picks: [],
  ws: null,
};
window.viewer = V;

let cameraId = 0;
const sentAt = new Map();
let backends = [];

// --- vector arithmetic (f64 arrays) ---
const add = (a, b) => a.map((x, i) => x + b[i]);
const sub = (a, b) => a.map((x, i) => x - b[i]);
const mul = (a, s) => a.map((x) => x * s);
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const len = (a) => Math.sqrt(dot(a, a));
const norm = (a) => mul(a, 1 / len(a));
// Rotates v about the unit axis k by angle t (Rodrigues).
function rotate(v, k, t) {
  const c = Math.cos(t), s = Math.sin(t);
  return add(add(mul(v, c), mul(cross(k, v), s)), mul(k, dot(k, v) * (1 - c)));
}

function send(obj) {
  if (V.ws && V.ws.readyState === WebSocket.OPEN) V.ws.send(JSON.stringify(obj));
}
V.send = send;

// A new camera: sent at once (the server drops the frame in flight).
function setCamera(cam) {
  V.cam = cam;
  cameraId += 1;
  sentAt.set(cameraId, performance.now());
  $("fov").value = Math.round(cam.fov);
  send({ type: "camera", id: cameraId, camera: cam });
}

function moved(cam) { return Object.assign({}, cam, { sensor: false }); }

function orbit(dx, dy) {
  const c = moved(V.cam);
  const up = norm(c.up);
  let off = sub(c.from, c.at);
  off = rotate(off, up, -dx * 0.006);
  const right = norm(cross(mul(off, -1), up));
  const next = rotate(off, right, -dy * 0.006);
  // Not over the poles.
  const a = Math.acos(Math.max(-1, Math.min(1, dot(norm(next), up))));
  if (a > 0.02 && a < Math.PI - 0.02) off = next;
  c.from = add(c.at, off);
  setCamera(c);
}

function pan(dx, dy) {
  const c = moved(V.cam);
  const off = sub(c.from, c.at);
  const fwd = norm(mul(off, -1));
  const right = norm(cross(fwd, c.up));
  const up = cross(right, fwd);
  const h = canvas.clientHeight || canvas.height;
  const s = (2 * len(off) * Math.tan((c.fov * Math.PI) / 360)) / h;
  const m = add(mul(right, -dx * s), mul(up, dy * s));
  c.from = add(c.from, m);
  c.at = add(c.at, m);
  setCamera(c);
}

function zoom(f) {
  const c = moved(V.cam);
  c.from = add(c.at, mul(sub(c.from, c.at), f));
  setCamera(c);
}

function fit() {
  const b = V.hello.bounds;
  if (!b) return;
  const c = moved(V.cam);
  const centre = mul(add(b[0], b[1]), 0.5);
  const r = 0.5 * len(sub(b[1], b[0]));
  const dir = norm(sub(c.from, c.at));
  const aspect = V.hello.width / V.hello.height;
  const half = Math.atan(Math.tan((c.fov * Math.PI) / 360) * Math.min(1, aspect));
  c.at = centre;
  c.from = add(centre, mul(dir, (r / Math.sin(half)) * 1.02));
  setCamera(c);
}

function setFov(f) {
  const c = moved(V.cam);
  c.fov = Math.max(5, Math.min(120, f));
  setCamera(c);
}

// The key light's direction of travel for azimuth `az` and elevation `el`
// (degrees) about the first view's up axis, azimuth 0 from the side the
// first view looks from.
function keyDirection(az, el) {
  const c = V.hello.camera;
  const u = norm(c.up);
  const f = sub(c.at, c.from);
  const fp = norm(sub(f, mul(u, dot(f, u))));
  const s = cross(fp, u);
  const a = (az * Math.PI) / 180, e = (el * Math.PI) / 180;
  const from = add(mul(add(mul(fp, -Math.cos(a)), mul(s, Math.sin(a))), Math.cos(e)), mul(u, Math.sin(e)));
  return from.map((x) => -Math.round(x * 1e4) / 1e4);
}

function aimLight() {
  send({ type: "light", direction: keyDirection(Number($("laz").value), Number($("lel").value)) });
}
V.aimLight = aimLight;

function sensorView() {
  if (V.hello.sensor) setCamera(Object.assign({}, V.hello.sensor));
}

// --- frames ---
async function onFrame(buf) {
  const dv = new DataView(buf);
  const n = dv.getUint32(0, true);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, n)));
  const bytes = new Uint8Array(buf, 4 + n);
  const bmp = await createImageBitmap(new Blob([bytes], { type: "image/png" }));
  ctx.imageSmoothingEnabled = header.stage === "preview";
  ctx.drawImage(bmp, 0, 0, canvas.width, canvas.height);
  const t0 = sentAt.get(header.camera);
  if (t0 !== undefined) {
    V.latencies.push(performance.now() - t0);
    sentAt.delete(header.camera);
  }
  header.received = performance.now();
  V.frames.push(header);
  if (header.show === "rgb" && header.stage !== "preview") {
    const kept = { header, bytes: bytes.slice() };
    if (header.stage === "full") V.lastFull = kept;
    if (header.stage === "refined") V.lastRefined = kept;
    V.lastShown = kept;
  }
  let line;
  if (header.stage === "diff") {
    const parts = header.differing.map((d, i) => `${header.backends[i + 1]} vs ${header.backends[0]}: ${d} pixels differ`);
    const secs = header.seconds.map((s, i) => `${header.backends[i]} ${s.toFixed(3)} s`);
    line = `difference overlay (red: differ) ${header.width}x${header.height} spp ${header.spp}\n${parts.join("; ")}\n${secs.join(", ")}`;
  } else {
    line = `${header.stage} ${header.width}x${header.height} spp ${header.spp}, ${header.backend}: ` +
      `${(header.seconds * 1000).toFixed(1)} ms, ${header.mrays_per_s.toFixed(2)} Mrays/s (${header.rays} rays)`;
  }
  $("info").textContent = line;
}

function download(name, blob) {
  const a = document.createElement("a");
  a.href = URL.createObjectURL(blob);
  a.download = name;
  document.body.appendChild(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(a.href), 1000);
}

function onText(m) {
  if (m.type === "hello") {
    V.hello = m;
    backends = m.backends;
    $("name").textContent = `${m.name} (${m.splats} splats)`;
    canvas.width = m.width;
    canvas.height = m.height;
    const sel = $("backend");
    sel.innerHTML = "";
    for (const b of m.backends) {
      const o = document.createElement("option");
      o.value = o.textContent = b;
      sel.appendChild(o);
    }
    sel.value = m.backend;
    $("sensor").disabled = !m.sensor;
    V.cam = m.camera;
    $("fov").value = Math.round(m.camera.fov);
  } else if (m.type === "error") {
    V.errors.push(m.message);
    $("err").textContent = "error: " + m.message;
  } else if (m.type === "scene") {
    V.sceneText = m.text;
    if (V.wantDownload) download("view.toml", new Blob([m.text], { type: "application/toml" }));
    V.wantDownload = false;
  } else if (m.type === "pick") {
    V.picks.push(m);
    const f = (x) => (typeof x === "number" ? x.toPrecision(6) : x);
    const lines = m.backends.map((b) => {
      const h = b.hit ? `splat ${b.hit.splat}, t ${f(b.hit.t)}, normal [${b.hit.normal.map(f).join(", ")}]` : "no hit";
      const c = b.candidates.map((k) => `${k.id}@${f(k.t)}`).join(" ");
      return `${b.backend}: ${h}; window: ${b.candidates.length} candidates ${c}`;
    });
    $("pick").textContent = `pixel (${m.x}, ${m.y})\n` + lines.join("\n");
  }
}

function connect() {
  const ws = new WebSocket(`ws://${location.host}/ws`);
  ws.binaryType = "arraybuffer";
  V.ws = ws;
  // Messages are handled one after the other, in the order they came: a
  // frame's decoding is asynchronous, and a later frame must not be drawn
  // (or kept) before an earlier one.
  let chain = Promise.resolve();
  ws.onmessage = (e) => {
    chain = chain
      .then(() => (typeof e.data === "string" ? onText(JSON.parse(e.data)) : onFrame(e.data)))
      .catch((err) => { V.errors.push(String(err)); $("err").textContent = "page error: " + err; });
  };
  ws.onclose = () => { $("err").textContent = "disconnected from the server"; };
}

// --- input ---
const pointers = new Map();
let downAt = null;
canvas.addEventListener("contextmenu", (e) => e.preventDefault());
canvas.addEventListener("pointerdown", (e) => {
  canvas.setPointerCapture(e.pointerId);
  pointers.set(e.pointerId, { x: e.clientX, y: e.clientY, button: e.button, shift: e.shiftKey });
  downAt = { x: e.clientX, y: e.clientY, moved: false };
});
canvas.addEventListener("pointermove", (e) => {
  const p = pointers.get(e.pointerId);
  if (!p || !V.cam) return;
  const dx = e.clientX - p.x, dy = e.clientY - p.y;
  if (dx === 0 && dy === 0) return;
  if (downAt && Math.hypot(e.clientX - downAt.x, e.clientY - downAt.y) > 3) downAt.moved = true;
  if (pointers.size === 2) {
    // Pinch: zoom by the change of the fingers' distance.
    const [a, b] = [...pointers.values()];
    const before = Math.hypot(a.x - b.x, a.y - b.y);
    p.x = e.clientX; p.y = e.clientY;
    const after = Math.hypot(a.x - b.x, a.y - b.y);
    if (before > 0 && after > 0) zoom(before / after);
    return;
  }
  p.x = e.clientX; p.y = e.clientY;
  if (p.button === 2 || p.button === 1 || p.shift) pan(dx, dy);
  else orbit(dx, dy);
});
function up(e) {
  pointers.delete(e.pointerId);
  if (downAt && !downAt.moved && V.hello && e.type === "pointerup") {
    const r = canvas.getBoundingClientRect();
    const x = Math.floor(((e.clientX - r.left) * V.hello.width) / r.width);
    const y = Math.floor(((e.clientY - r.top) * V.hello.height) / r.height);
    send({ type: "pick", x, y });
  }
  downAt = null;
}
canvas.addEventListener("pointerup", up);
canvas.addEventListener("pointercancel", up);
canvas.addEventListener("wheel", (e) => {
  e.preventDefault();
  if (V.cam) zoom(Math.exp(e.deltaY * 0.001));
}, { passive: false });

document.addEventListener("keydown", (e) => {
  if (!V.cam || e.target.tagName === "SELECT" || e.target.tagName === "INPUT") return;
  const step = 20;
  const arrows = { ArrowLeft: [-step, 0], ArrowRight: [step, 0], ArrowUp: [0, -step], ArrowDown: [0, step] };
  if (arrows[e.key]) {
    const [dx, dy] = arrows[e.key];
    if (e.shiftKey) pan(dx, dy); else orbit(dx, dy);
  } else if (e.key === "+" || e.key === "=") zoom(0.85);
  else if (e.key === "-" || e.key === "_") zoom(1 / 0.85);
  else if (e.key === "[") setFov(V.cam.fov - 3);
  else if (e.key === "]") setFov(V.cam.fov + 3);
  else if (e.key === "f") fit();
  else if (e.key === "s") sensorView();
  else if (e.key === "d") send({ type: "diff" });
  else if (e.key === "b") {
    const sel = $("backend");
    sel.value = backends[(backends.indexOf(sel.value) + 1) % backends.length];
    send({ type: "backend", name: sel.value });
  } else return;
  e.preventDefault();
});

$("backend").addEventListener("change", (e) => send({ type: "backend", name: e.target.value }));
$("shading").addEventListener("change", (e) => send({ type: "shading", mode: e.target.value }));
$("show").addEventListener("change", (e) => send({ type: "show", show: e.target.value }));
$("fov").addEventListener("input", (e) => setFov(Number(e.target.value)));
$("fit").addEventListener("click", fit);
$("laz").addEventListener("input", aimLight);
$("lel").addEventListener("input", aimLight);
$("lreset").addEventListener("click", () => send({ type: "light", direction: null }));
$("sensor").addEventListener("click", sensorView);
$("diff").addEventListener("click", () => send({ type: "diff" }));
$("savescene").addEventListener("click", () => {
  V.wantDownload = true;
  send({ type: "save_scene", spp: V.lastShown ? V.lastShown.header.spp : undefined });
});
$("saveimage").addEventListener("click", () => {
  if (V.lastShown) download("view.png", new Blob([V.lastShown.bytes], { type: "image/png" }));
});

connect();
