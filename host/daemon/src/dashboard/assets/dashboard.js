// The bench dashboard: follows the daemon's live feed (GET /v1/events, Server-Sent
// Events) and status (GET /v1/status, once a second), draws the traces and the a–u_s curve
// on <canvas>, and sends changes with the CSRF token the page was served with.
//
// Display rate: the daemon already decimates the 2 kHz sample stream to at most one
// `sample` event per 10 ms of device time; here every event only updates arrays, and
// drawing happens at most once per animation frame (requestAnimationFrame), whatever the
// event rate. The emergency stop is sent on pointerdown (no wait for the click) and by
// the Esc key, with a fetch of its own that nothing else queues behind.
'use strict';

const CSRF = document.querySelector('meta[name="tactile-csrf"]').content;
const WINDOW_S = 10; // seconds of trace shown
const $ = (id) => document.getElementById(id);

const state = {
  trace: [], // [device s, pressure kPa, setpoint kPa|null, stage mm|null, load N|null]
  setpoint: null,
  points: [], // [u_s, a, cycle]
  model: [],
  fit: null,
  finalFit: false,
  curveJob: null,
  jobs: new Map(),
  events: 0,
  draws: 0,
  frames: 0,
  lagged: 0,
};

// ---- requests ----------------------------------------------------------------------

// The browser opens at most 6 connections to one host (HTTP/1.1) and queues the rest. The
// feed holds one; the page's other requests go through this limiter (2 at a time, record
// plots load one after another), so a connection is always free for the stop, which does
// not use it.
const MAX_IN_FLIGHT = 2;
let inFlight = 0;
const waiting = [];
async function limited(fn) {
  // A waiter is handed the finishing request's slot, so at most MAX_IN_FLIGHT run.
  if (inFlight >= MAX_IN_FLIGHT) await new Promise((r) => waiting.push(r));
  else inFlight++;
  try { return await fn(); } finally {
    const next = waiting.shift();
    if (next) next(); else inFlight--;
  }
}

function api(method, path, body) {
  return limited(() => request(method, path, body));
}

async function request(method, path, body) {
  const init = { method, cache: 'no-store', headers: {} };
  if (method !== 'GET') init.headers['X-Tactile-CSRF'] = CSRF;
  if (body !== undefined) {
    init.headers['Content-Type'] = 'application/json';
    init.body = JSON.stringify(body);
  }
  const r = await fetch(path, init);
  let data = null;
  try { data = await r.json(); } catch (_) { data = null; }
  return { ok: r.ok, status: r.status, data };
}

function errorText(res) {
  return (res.data && res.data.error) || `HTTP ${res.status}`;
}

// ---- emergency stop ----------------------------------------------------------------

let stopPending = false;
function emergencyStop() {
  if (stopPending) return;
  stopPending = true;
  const t0 = performance.now();
  $('stop-result').textContent = 'stopping…';
  fetch('/v1/stop', {
    method: 'POST', cache: 'no-store', keepalive: true,
    headers: { 'X-Tactile-CSRF': CSRF },
  }).then(async (r) => {
    const d = await r.json().catch(() => ({}));
    const ms = (performance.now() - t0).toFixed(0);
    $('stop-result').textContent = r.ok
      ? `stop ${d.acknowledged ? 'acknowledged' : 'sent, NOT acknowledged'} (${ms} ms)`
      : `stop refused: ${d.error || r.status}`;
    $('stop-result').dataset.outcome = r.ok ? (d.acknowledged ? 'acknowledged' : 'sent') : 'refused';
  }).catch((e) => {
    $('stop-result').textContent = `stop failed: ${e}`;
    $('stop-result').dataset.outcome = 'failed';
  }).finally(() => { stopPending = false; });
}
$('estop').addEventListener('pointerdown', (e) => { if (e.button === 0) emergencyStop(); });
// Keyboard activation (Enter, Space) arrives as a click with detail 0.
$('estop').addEventListener('click', (e) => { if (e.detail === 0) emergencyStop(); });
document.addEventListener('keydown', (e) => { if (e.key === 'Escape') emergencyStop(); });

$('clear-fault').addEventListener('click', async () => {
  const r = await api('POST', '/v1/clear-fault');
  $('clear-fault-result').textContent = r.ok ? 'cleared' : errorText(r);
  refreshStatus();
});

// ---- plots -------------------------------------------------------------------------

function niceTicks(lo, hi, n) {
  const span = hi - lo || 1;
  const raw = span / n;
  const mag = Math.pow(10, Math.floor(Math.log10(raw)));
  const step = [1, 2, 5, 10].map((m) => m * mag).find((s) => s >= raw) || raw;
  const ticks = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) ticks.push(v);
  return ticks;
}

function range(values, pad, fixed) {
  let lo = Infinity, hi = -Infinity;
  for (const v of values) { if (v < lo) lo = v; if (v > hi) hi = v; }
  if (fixed) { lo = Math.min(lo, fixed[0]); hi = Math.max(hi, fixed[1]); }
  if (!isFinite(lo)) { lo = 0; hi = 1; }
  if (hi - lo < 1e-9) { lo -= 0.5; hi += 0.5; }
  const p = (hi - lo) * pad;
  return [lo - p, hi + p];
}

// series: {data: [[x, y]...], color, dots?}
function plot(canvas, series, opts) {
  const ratio = window.devicePixelRatio || 1;
  const w = canvas.clientWidth || canvas.width, h = Math.round(w * canvas.height / canvas.width);
  if (canvas._w !== w * ratio) { canvas._w = w * ratio; canvas.width = w * ratio; canvas.height = h * ratio; }
  const ctx = canvas.getContext('2d');
  ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
  ctx.clearRect(0, 0, w, h);
  const L = 58, R = 10, T = 8, B = 28;
  const xs = [], ys = [];
  for (const s of series) for (const p of s.data) { xs.push(p[0]); ys.push(p[1]); }
  const [x0, x1] = opts.x || range(xs, 0, null);
  const [y0, y1] = range(ys, 0.08, opts.yMin);
  const X = (x) => L + (x - x0) / (x1 - x0) * (w - L - R);
  const Y = (y) => h - B - (y - y0) / (y1 - y0) * (h - T - B);
  ctx.font = '11px system-ui, sans-serif';
  ctx.strokeStyle = '#dde'; ctx.fillStyle = '#556'; ctx.lineWidth = 1;
  ctx.textAlign = 'right'; ctx.textBaseline = 'middle';
  for (const t of niceTicks(y0, y1, 5)) {
    ctx.beginPath(); ctx.moveTo(L, Y(t)); ctx.lineTo(w - R, Y(t)); ctx.stroke();
    ctx.fillText(+t.toPrecision(6) + '', L - 4, Y(t));
  }
  ctx.textAlign = 'center'; ctx.textBaseline = 'top';
  for (const t of niceTicks(x0, x1, 6)) {
    ctx.beginPath(); ctx.moveTo(X(t), T); ctx.lineTo(X(t), h - B); ctx.stroke();
    ctx.fillText(+t.toPrecision(6) + '', X(t), h - B + 3);
  }
  ctx.textAlign = 'right';
  ctx.fillText(opts.xLabel || '', w - R, h - 13);
  if (opts.yLabel) {
    ctx.save();
    ctx.translate(2, T + (h - T - B) / 2);
    ctx.rotate(-Math.PI / 2);
    ctx.textAlign = 'center'; ctx.textBaseline = 'top';
    ctx.fillText(opts.yLabel, 0, 0);
    ctx.restore();
  }
  ctx.textAlign = 'left';
  let legendX = L + 6;
  for (const s of series) {
    ctx.strokeStyle = s.color; ctx.fillStyle = s.color; ctx.lineWidth = s.width || 1.5;
    if (s.dots) {
      for (const p of s.data) ctx.fillRect(X(p[0]) - 1.5, Y(p[1]) - 1.5, 3, 3);
    } else {
      ctx.beginPath();
      let pen = false, last = -Infinity;
      for (const p of s.data) {
        if (p[1] === null || p[1] === undefined) { pen = false; continue; }
        // A gap in the data (the stream paused) is left open, not bridged by a line.
        if (opts.maxGap && p[0] - last > opts.maxGap) pen = false;
        if (pen) ctx.lineTo(X(p[0]), Y(p[1])); else ctx.moveTo(X(p[0]), Y(p[1]));
        pen = true; last = p[0];
      }
      ctx.stroke();
    }
    if (s.label) { ctx.textBaseline = 'top'; ctx.fillText(s.label, legendX, T + 2); legendX += ctx.measureText(s.label).width + 14; }
  }
}

let rafPending = false;
function schedule() {
  if (!rafPending) { rafPending = true; requestAnimationFrame(draw); }
}

function draw() {
  rafPending = false;
  state.draws++;
  const tr = state.trace;
  // Time axis relative to the newest sample (device time).
  const now = tr.length ? tr[tr.length - 1][0] : 0;
  const xr = [-WINDOW_S, 0];
  plot($('plot-pressure'), [
    { data: tr.map((r) => [r[0] - now, r[1]]), color: '#1565c0', label: 'pressure' },
    { data: tr.map((r) => [r[0] - now, r[2]]), color: '#e65100', label: 'setpoint', width: 1 },
  ], { x: xr, xLabel: 'time (s)', yLabel: 'kPa', yMin: [0, 1], maxGap: 0.1 });
  plot($('plot-stage'), [
    { data: tr.map((r) => [r[0] - now, r[3]]), color: '#2e7d32', label: 'stage (mm)' },
    { data: tr.map((r) => [r[0] - now, r[4]]), color: '#6a1b9a', label: 'load (N)', width: 1 },
  ], { x: xr, xLabel: 'time (s)', maxGap: 0.1 });
  const pts = state.points.filter((p) => p[1] > 0);
  plot($('plot-curve'), [
    { data: pts.map((p) => [p[0], p[1]]), color: '#1565c0', dots: true, label: 'measured' },
    { data: state.model, color: '#c62828', width: 2, label: 'model at the estimate' },
  ], { xLabel: 'u_s (mm)', yLabel: 'a (mm)', yMin: [0, 0.5] });
  $('points-count').textContent = String(state.points.length);
}

// ---- the live feed -----------------------------------------------------------------

function fmt(v, digits) {
  return v === null || v === undefined ? '–' : Number(v).toFixed(digits);
}

function showFit() {
  const f = state.fit;
  if (!f) { $('e2').textContent = 'E2: –'; $('fit-state').textContent = ''; return; }
  $('e2').textContent = `E2 = ${f.modulus_kpa.toFixed(1)} kPa (95 % CI ${f.ci95_kpa[0].toFixed(1)} .. ${f.ci95_kpa[1].toFixed(1)} kPa)`;
  $('fit-state').textContent = state.finalFit ? 'final fit' : `running fit, ${f.points} points`;
  $('fit-state').className = 'badge' + (state.finalFit ? ' ok' : '');
  $('fit-state').dataset.final = state.finalFit ? 'true' : 'false';
}

// The pressure an experiment job runs at now: the set one, or with "auto" the probe's until
// the choice is made, then the chosen one.
function runPressure(j) {
  const e = j.experiment;
  if (!e) return null;
  if (typeof e.pressure_kpa === 'number') return e.pressure_kpa;
  if (j.pressure_choice) return j.pressure_choice.chosen_kpa;
  return typeof e.probe_pressure_kpa === 'number' ? e.probe_pressure_kpa : 6;
}

// While an experiment runs the daemon does not poll the device's status (the job owns the
// link): its setpoint is the experiment's pressure.
function currentSetpoint() {
  for (const j of state.jobs.values()) {
    if (j.state === 'running' && j.experiment) return runPressure(j);
  }
  return state.setpoint;
}

// The pressure part of a job's line: "6 kPa", "auto: probe at 6 kPa", or "auto: 15 kPa
// (probe at 6 kPa read 640.2 kPa, predicted error 1.3 %)".
function pressureText(j) {
  const e = j.experiment;
  if (!e) return '';
  if (typeof e.pressure_kpa === 'number') return `${e.pressure_kpa} kPa`;
  const c = j.pressure_choice;
  if (!c) return `auto: probe at ${runPressure(j)} kPa`;
  return `auto: ${c.chosen_kpa} kPa (probe at ${c.probe_kpa} kPa read ${c.probe_modulus_kpa.toFixed(1)} kPa, predicted error ${(100 * c.predicted_relative_se).toFixed(1)} %)`;
}

const handlers = {
  sample(e) {
    const t = e.device_time_us * 1e-6;
    const tr = state.trace;
    if (tr.length && t < tr[tr.length - 1][0]) tr.length = 0; // the device restarted
    tr.push([t, e.pressure_kpa, currentSetpoint(), e.stage_mm, e.load_n]);
    let k = 0;
    while (k < tr.length && t - tr[k][0] > WINDOW_S) k++;
    if (k > 64) tr.splice(0, k);
    $('v-pressure').textContent = fmt(e.pressure_kpa, 3);
    $('v-stage').textContent = fmt(e.stage_mm, 4);
    $('v-load').textContent = fmt(e.load_n, 4);
  },
  frame(e) {
    state.frames++;
    $('v-radius').textContent = fmt(e.a_mm, 3);
  },
  point(e) {
    state.points.push([e.u_s_mm, e.a_mm, e.cycle]);
  },
  fit(e) {
    if (state.finalFit && !e.final_fit) return;
    state.fit = e.fit; state.model = e.model; state.finalFit = e.final_fit;
    showFit();
  },
  job(e) {
    const j = e.job;
    const prev = state.jobs.get(j.id);
    const newRun = j.kind === 'experiment' && j.state === 'running'
      && (((!prev || prev.state !== 'running') && state.curveJob !== j.id)
        // the automatic choice was made: the measurement's curve starts afresh
        || (j.pressure_choice && prev && !prev.pressure_choice));
    if (newRun) {
      state.curveJob = j.id; state.points = []; state.model = []; state.fit = null; state.finalFit = false;
      $('curve-job').textContent = String(j.id);
      showFit();
    }
    state.jobs.set(j.id, j);
    showJobs();
    if (j.state !== 'queued' && j.state !== 'running') refreshRecords();
  },
  link(e) { showLink(e.connected, e.port); $('message').textContent = e.message; },
  fault(e) { showFaults(e.latched); },
  stats(e) {
    $('v-samples').textContent = String(e.samples_received);
    $('v-lost').textContent = String(e.blocks_lost);
    $('v-frame-errors').textContent = String(e.frame_errors);
    $('v-frames').textContent = `${e.frames_measured} (${e.frames_dropped} dropped)`;
  },
  emergency_stop(e) {
    $('message').textContent = `emergency stop ${e.acknowledged ? 'acknowledged' : 'NOT acknowledged'} by the controller`;
  },
  lagged(e) { state.lagged += e.skipped; $('v-lagged').textContent = String(state.lagged); },
};

let feed = null;
let feedRetry = null;
function openFeed() {
  if (feed) feed.close();
  feed = new EventSource('/v1/events');
  feed.onopen = () => {
    $('feed-state').textContent = 'feed: live';
    $('feed-state').className = 'badge ok';
    document.body.dataset.feed = 'live';
    resync();
  };
  feed.onerror = () => {
    $('feed-state').textContent = 'feed: reconnecting…';
    $('feed-state').className = 'badge bad';
    document.body.dataset.feed = 'down';
    // The browser retries by itself unless the connection was refused outright.
    if (feed.readyState === EventSource.CLOSED && !feedRetry) {
      feedRetry = setTimeout(() => { feedRetry = null; openFeed(); }, 1000);
    }
  };
  for (const name of Object.keys(handlers)) {
    feed.addEventListener(name, (m) => {
      state.events++;
      let e;
      try { e = JSON.parse(m.data); } catch (_) { return; }
      handlers[name](e);
      schedule();
    });
  }
}

// ---- status, jobs, records ---------------------------------------------------------

function showLink(connected, port) {
  $('link-state').textContent = connected ? `device: ${port || 'connected'}` : 'device: not connected';
  $('link-state').className = 'badge ' + (connected ? 'ok' : 'bad');
}

function showFaults(latched) {
  $('fault-banner').hidden = !latched || latched.length === 0;
  $('fault-names').textContent = (latched || []).join(', ');
}

let statusPending = false;
async function refreshStatus() {
  // One status request at a time: a daemon that does not answer does not pile them up.
  if (statusPending) return;
  statusPending = true;
  let r;
  try { r = await api('GET', '/v1/status'); } catch (_) { return; } finally { statusPending = false; }
  if (!r.ok || !r.data) return;
  const s = r.data;
  state.setpoint = s.setpoint_kpa;
  showLink(s.connected, s.port);
  showFaults(s.faults);
  $('v-setpoint').textContent = fmt(currentSetpoint(), 2);
  $('v-vent').textContent = s.vent_open === null ? '–' : (s.vent_open ? 'open' : 'closed');
  $('v-pump').textContent = s.pump_duty === null ? '–' : `${(s.pump_duty * 100).toFixed(0)} %`;
  $('v-port').textContent = s.port || '–';
  $('v-gaps').textContent = String(s.gaps.length);
  $('v-estops').textContent = String(s.emergency_stops);
  if (s.link) {
    $('v-samples').textContent = String(s.link.samples_received);
    $('v-lost').textContent = String(s.link.blocks_lost);
    $('v-frame-errors').textContent = String(s.link.frame_errors);
  }
  if (s.pressure_kpa !== null && !state.trace.length) $('v-pressure').textContent = fmt(s.pressure_kpa, 3);
}

function showJobs() {
  const list = $('jobs');
  list.textContent = '';
  const jobs = [...state.jobs.values()].sort((a, b) => b.id - a.id);
  const active = jobs.filter((j) => j.state === 'running' || j.state === 'queued');
  const done = jobs.filter((j) => j.state !== 'running' && j.state !== 'queued').slice(0, 8);
  for (const j of [...active, ...done]) {
    const li = document.createElement('li');
    li.dataset.job = String(j.id);
    li.dataset.state = j.state;
    let text = `#${j.id} ${j.kind} ${j.state}`;
    if (j.experiment) text += ` at ${pressureText(j)}`;
    if (j.pressure_choice) li.dataset.chosenKpa = String(j.pressure_choice.chosen_kpa);
    if (j.state === 'running') text += ` ${(j.progress * 100).toFixed(0)} %`;
    if (j.fit && !(j.message || '').includes('E2')) text += ` — E2 ${j.fit.modulus_kpa.toFixed(1)} kPa (${j.fit.ci95_kpa[0].toFixed(1)} .. ${j.fit.ci95_kpa[1].toFixed(1)})`;
    if (j.message) text += ` — ${j.message}`;
    li.textContent = text;
    if (j.state === 'running' || j.state === 'queued') {
      const b = document.createElement('button');
      b.type = 'button'; b.textContent = 'Cancel'; b.className = 'cancel';
      b.addEventListener('click', async () => {
        const r = await api('DELETE', `/v1/experiments/${j.id}`);
        if (!r.ok) $('form-result').textContent = errorText(r);
      });
      li.appendChild(b);
    }
    list.appendChild(li);
  }
}

async function refreshJobs() {
  const r = await api('GET', '/v1/experiments');
  if (!r.ok) return;
  state.jobs = new Map(r.data.map((j) => [j.id, j]));
  showJobs();
}

function link(href, text) {
  const a = document.createElement('a');
  a.href = href; a.textContent = text; a.download = '';
  return a;
}

async function showRecord(name) {
  const box = $('record-detail');
  box.textContent = '';
  const h = document.createElement('h2');
  h.textContent = name;
  box.appendChild(h);
  const r = await api('GET', `/v1/records/${encodeURIComponent(name)}`);
  if (!r.ok) { box.append(errorText(r)); return; }
  const files = r.data;
  if (files.includes('fit.json')) {
    const f = await api('GET', `/v1/records/${encodeURIComponent(name)}/fit.json`);
    const p = document.createElement('p');
    const fit = f.data && (f.data.fit || f.data);
    p.className = 'record-fit';
    p.textContent = fit && fit.modulus_kpa !== undefined
      ? `E2 = ${Number(fit.modulus_kpa).toFixed(1)} kPa` + (fit.ci95_kpa ? ` (95 % CI ${Number(fit.ci95_kpa[0]).toFixed(1)} .. ${Number(fit.ci95_kpa[1]).toFixed(1)} kPa)` : '')
      : 'fit.json';
    box.appendChild(p);
  }
  if (files.includes('pressure_choice.json')) {
    const c = await api('GET', `/v1/records/${encodeURIComponent(name)}/pressure_choice.json`);
    const p = document.createElement('p');
    p.className = 'record-pressure';
    const d = c.data;
    if (c.ok && d && typeof d.chosen_kpa === 'number') {
      p.dataset.chosenKpa = String(d.chosen_kpa);
      p.textContent = `pressure chosen automatically: ${d.chosen_kpa} kPa (predicted error ${(100 * d.predicted_relative_se).toFixed(1)} %); probe at ${d.probe_kpa} kPa read ${Number(d.probe_modulus_kpa).toFixed(1)} kPa (record ${name}/probe)`;
    } else {
      p.textContent = 'pressure_choice.json';
    }
    box.appendChild(p);
  }
  for (const file of files.filter((f) => f.endsWith('.svg'))) {
    const img = document.createElement('img');
    img.alt = file;
    box.appendChild(img);
    await limited(() => new Promise((done) => {
      img.onload = done; img.onerror = done;
      img.src = `/v1/records/${encodeURIComponent(name)}/${encodeURIComponent(file)}`;
    }));
  }
  const ul = document.createElement('ul');
  ul.className = 'list';
  for (const file of files) {
    const li = document.createElement('li');
    li.appendChild(link(`/v1/records/${encodeURIComponent(name)}/${encodeURIComponent(file)}`, file));
    ul.appendChild(li);
  }
  box.appendChild(ul);
}

async function refreshRecords() {
  const r = await api('GET', '/v1/records');
  if (r.ok) {
    const list = $('record-list');
    list.textContent = '';
    for (const rec of r.data.slice().reverse()) {
      const li = document.createElement('li');
      const a = document.createElement('a');
      a.textContent = rec.name;
      a.addEventListener('click', () => showRecord(rec.name));
      li.appendChild(a);
      li.append(` ${rec.status || ''}`);
      list.appendChild(li);
    }
  }
  const c = await api('GET', '/v1/calibrations');
  if (c.ok) {
    const list = $('calibration-list');
    list.textContent = '';
    for (const name of c.data.slice().reverse()) {
      const li = document.createElement('li');
      li.appendChild(link(`/v1/calibrations/${encodeURIComponent(name)}`, name));
      list.appendChild(li);
    }
  }
}

async function refreshCurve() {
  const r = await api('GET', '/v1/live');
  if (!r.ok) return;
  const c = r.data;
  state.curveJob = c.job;
  state.points = c.points;
  state.fit = c.fit; state.model = c.model; state.finalFit = c.final_fit;
  $('curve-job').textContent = c.job === null ? '–' : String(c.job);
  showFit();
  schedule();
}

function resync() {
  refreshStatus(); refreshJobs(); refreshRecords(); refreshCurve();
}

// ---- the experiment form -----------------------------------------------------------

// The input a request field comes from, where the names differ.
const FIELD_INPUT = { probe_pressure_kpa: 'pressure_kpa' };

function showPressureMode() {
  const auto = $('pressure-auto').checked;
  $('pressure-label').textContent = auto ? 'probe pressure (kPa)' : 'pressure (kPa)';
  $('pressure-auto-help').hidden = !auto;
}
$('pressure-auto').addEventListener('change', showPressureMode);
showPressureMode();

$('experiment-form').addEventListener('submit', async (ev) => {
  ev.preventDefault();
  const form = ev.target;
  for (const s of form.querySelectorAll('.field-error')) s.textContent = '';
  for (const i of form.querySelectorAll('input')) i.classList.remove('invalid');
  const body = {};
  for (const input of form.querySelectorAll('input')) {
    const v = input.value.trim();
    if (input.type === 'checkbox') continue;
    if (input.type === 'number') {
      if (v === '') continue; // the API's default
      body[input.name] = Number(v);
    } else {
      body[input.name] = v;
    }
  }
  if ($('pressure-auto').checked) {
    // The pressure field then sets the probe's pressure.
    if (body.pressure_kpa !== undefined) body.probe_pressure_kpa = body.pressure_kpa;
    body.pressure_kpa = 'auto';
  }
  $('form-result').textContent = 'submitting…';
  $('form-result').className = '';
  let r;
  try { r = await api('POST', '/v1/experiments', body); } catch (e) {
    $('form-result').textContent = `not sent: ${e}`; return;
  }
  if (r.ok) {
    $('form-result').textContent = `queued as job ${r.data.id}`;
    $('form-result').dataset.job = String(r.data.id);
    // The job may already have started (and its feed event arrived): keep the newer state.
    if (!state.jobs.has(r.data.id)) state.jobs.set(r.data.id, r.data);
    showJobs();
    return;
  }
  $('form-result').className = 'error';
  $('form-result').textContent = errorText(r);
  for (const f of (r.data && r.data.fields) || []) {
    const span = form.querySelector(`.field-error[data-field="${f.field}"]`);
    if (span) span.textContent = f.reason;
    const input = form.querySelector(`input[name="${FIELD_INPUT[f.field] || f.field}"]`);
    if (input) input.classList.add('invalid');
  }
});

$('calibrate').addEventListener('click', async () => {
  const r = await api('POST', '/v1/calibrations');
  $('calibrate-result').textContent = r.ok ? `queued as job ${r.data.id}` : errorText(r);
});

// ---- start -------------------------------------------------------------------------

setInterval(() => {
  $('perf').textContent = `${state.events} events/s, ${state.draws} draws/s`;
  document.body.dataset.eventsPerS = String(state.events);
  document.body.dataset.drawsPerS = String(state.draws);
  $('v-fps').textContent = state.frames ? `(${state.frames} camera frames/s)` : '';
  state.events = 0; state.draws = 0; state.frames = 0;
}, 1000);
setInterval(refreshStatus, 1000);
openFeed();
resync();
