// The web dashboard in a real browser (headless Chromium driven by playwright-core):
// `tactile daemon --sim` is started as a user starts it, the browser logs in through the
// printed one-time address, calibrates, runs an experiment through the form (field errors
// first), follows the live points and the final E2, presses the stop button in the middle
// of a second run and checks through the JSON API that the vent opened and the job ended
// partial; a page on another port cannot change anything; the page reconnects by itself
// after the daemon restarts, shows the fault the new bench latches and clears it.
//
// Usage: node dashboard.test.js --tactile PATH [--screenshot FILE]
// Prints one line per check and `N passed, M failed` last; exits 1 on any failure.

import { spawn } from 'node:child_process';
import { mkdtempSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import { createServer } from 'node:http';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { chromium } from 'playwright-core';

const args = process.argv.slice(2);
const opt = (name) => { const k = args.indexOf(name); return k >= 0 ? args[k + 1] : undefined; };
const TACTILE = opt('--tactile');
const SCREENSHOT = opt('--screenshot');
if (!TACTILE) { console.error('usage: node dashboard.test.js --tactile PATH [--screenshot FILE]'); process.exit(2); }

// Timeouts. The machine that runs CI may have 2 cores shared with other builds, and the
// simulated bench runs in real time there: an experiment of 2 indentations takes about
// 10 s unloaded; a calibration about as long. Waits are 6-10 times that so a starved run
// still passes, while a real hang still fails well inside the tier's ~2 minute budget.
const CONNECT_MS = 30_000; // daemon start and first link to hil-sim (1-2 s unloaded)
const JOB_MS = 90_000; // a calibration or a 2-indentation experiment (10-15 s unloaded)
const UI_MS = 15_000; // a page reaction to an event (well under 1 s unloaded)

const results = [];
function check(name, ok, detail = '') {
  results.push({ name, ok });
  console.log(`${ok ? 'ok' : 'not ok'} - ${name}${detail ? ` (${detail})` : ''}`);
  return ok;
}

const dir = mkdtempSync(join(tmpdir(), 'tactile-dashboard-'));
const tokenFile = join(dir, 'token');
let daemon = null;
let daemonLog = '';

function startDaemon(listen, extra = []) {
  return new Promise((resolve, reject) => {
    const child = spawn(TACTILE, ['daemon', '--sim', '--listen', listen, '--records', join(dir, 'records'),
      '--token-file', tokenFile, ...extra], { stdio: ['ignore', 'ignore', 'pipe'] });
    let text = '';
    const timer = setTimeout(() => reject(new Error(`daemon did not print its addresses:\n${text}`)), CONNECT_MS);
    child.stderr.on('data', (d) => {
      text += d; daemonLog += d;
      const listening = /listening on http:\/\/(\S+) /.exec(text);
      const login = /dashboard: (http:\/\/\S+\/\?token=[0-9a-f]{64})/.exec(text);
      if (listening && login) { clearTimeout(timer); resolve({ child, addr: listening[1], login: login[1] }); }
    });
    child.on('exit', (code) => { clearTimeout(timer); reject(new Error(`daemon exited (${code}):\n${text}`)); });
  });
}

function stopDaemon(child) {
  return new Promise((resolve) => {
    if (child.exitCode !== null) { resolve(); return; }
    child.removeAllListeners('exit');
    child.on('exit', () => resolve());
    child.kill('SIGTERM');
  });
}

const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

async function until(what, fn, ms) {
  const t0 = Date.now();
  for (;;) {
    const v = await fn();
    if (v) return v;
    if (Date.now() - t0 > ms) throw new Error(`timed out after ${ms} ms: ${what}`);
    await sleep(200);
  }
}

let base, token;
async function apiGet(path) {
  const r = await fetch(base + path, { headers: { Authorization: `Bearer ${token}` } });
  return r.json();
}

async function main() {
  daemon = await startDaemon('127.0.0.1:0');
  base = `http://${daemon.addr}`;
  token = readFileSync(tokenFile, 'utf8').trim();
  await until('device connected', async () => (await apiGet('/v1/status')).connected, CONNECT_MS);

  const browser = await chromium.launchPersistentContext(join(dir, 'profile'), {
    executablePath: '/usr/bin/chromium',
    headless: true,
    args: ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
      '--disable-background-networking', '--disable-component-update', '--disable-sync'],
    viewport: { width: 1500, height: 1250 },
  });
  try {
    await run(browser);
  } finally {
    await browser.close();
  }
}

async function run(browser) {
  const page = browser.pages()[0] || await browser.newPage();
  page.setDefaultTimeout(UI_MS);
  // Uncaught script errors (failed requests, e.g. a 422, are logged by the browser too,
  // and are expected here).
  const pageErrors = [];
  page.on('pageerror', (e) => pageErrors.push(String(e)));

  // --- login ------------------------------------------------------------------------
  const redirects = [];
  page.on('response', (r) => { if (r.status() === 303) redirects.push(r.headers()['location']); });
  const arrived = await page.goto(daemon.login);
  check('login address answers 303 to the clean address', redirects.length === 1 && redirects[0] === '/',
    `redirects ${JSON.stringify(redirects)}`);
  check('the page is at / without the token', page.url() === `${base}/` && arrived.status() === 200, page.url());
  const cookies = await browser.cookies(base);
  const session = cookies.find((c) => c.name.startsWith('tactile_session_'));
  check('session cookie is HttpOnly and SameSite=Strict', session && session.httpOnly && session.sameSite === 'Strict',
    JSON.stringify(session && { httpOnly: session.httpOnly, sameSite: session.sameSite }));
  const again = await browser.newPage();
  const reused = await again.goto(daemon.login);
  check('the login address works once', reused.status() === 403, `status ${reused.status()}`);
  await again.close();
  await page.waitForSelector('body[data-feed="live"]');
  check('live feed connected', true);

  // --- calibration through the page --------------------------------------------------
  await page.click('#calibrate');
  const calId = Number(await until('calibration queued', async () => {
    const t = await page.textContent('#calibrate-result');
    return /job (\d+)/.exec(t)?.[1];
  }, UI_MS));
  const cal = await until('calibration done', async () => {
    const j = await apiGet(`/v1/experiments/${calId}`);
    return ['complete', 'partial', 'failed', 'cancelled'].includes(j.state) && j;
  }, JOB_MS);
  check('calibration from the page completes', cal.state === 'complete', cal.message);
  await page.waitForSelector('#calibration-list li');

  // --- field errors ------------------------------------------------------------------
  await page.fill('input[name=depth_mm]', '9');
  await page.fill('input[name=repeats]', '0');
  await page.click('#submit-experiment');
  await page.waitForSelector('.field-error[data-field="depth_mm"]:not(:empty)');
  const depthErr = await page.textContent('.field-error[data-field="depth_mm"]');
  const repErr = await page.textContent('.field-error[data-field="repeats"]');
  const pErr = await page.textContent('.field-error[data-field="pressure_kpa"]');
  check('the API\'s validation messages appear at their fields',
    depthErr.includes('outside') && repErr.includes('outside') && pErr === '', `${depthErr} | ${repErr}`);

  // --- the automatic pressure choice: the pressure field becomes the probe's --------
  await page.check('#pressure-auto');
  const autoLabel = await page.textContent('#pressure-label');
  await page.fill('input[name=pressure_kpa]', '40');
  await page.click('#submit-experiment');
  await page.waitForSelector('.field-error[data-field="probe_pressure_kpa"]:not(:empty)');
  const probeErr = await page.textContent('.field-error[data-field="probe_pressure_kpa"]');
  const marked = await page.$eval('input[name=pressure_kpa]', (i) => i.classList.contains('invalid'));
  check('with "auto" the pressure field is the probe\'s and its error shows there',
    autoLabel.includes('probe') && probeErr.includes('outside') && marked, `${autoLabel} | ${probeErr} | ${marked}`);
  await page.uncheck('#pressure-auto');
  await page.fill('input[name=pressure_kpa]', '6');

  // --- an experiment to the end ------------------------------------------------------
  await page.fill('input[name=depth_mm]', '1.2');
  await page.fill('input[name=repeats]', '2');
  await page.fill('input[name=label]', 'browser test');
  await page.click('#submit-experiment');
  const jobId = Number(await until('experiment queued', async () =>
    page.getAttribute('#form-result', 'data-job'), UI_MS));
  const perf = { events: [], draws: [] };
  let sawRunningFit = false;
  let livePoints = 0;
  const t0 = Date.now();
  for (;;) {
    const s = await page.evaluate(() => ({
      points: Number(document.getElementById('points-count').textContent),
      fit: document.getElementById('fit-state').dataset.final,
      e2: document.getElementById('e2').textContent,
      events: Number(document.body.dataset.eventsPerS || 0),
      draws: Number(document.body.dataset.drawsPerS || 0),
    }));
    perf.events.push(s.events); perf.draws.push(s.draws);
    if (s.fit === 'false') sawRunningFit = true;
    livePoints = Math.max(livePoints, s.points);
    if (s.fit === 'true') break;
    if (Date.now() - t0 > JOB_MS) break;
    await sleep(250);
  }
  check('live a-u_s points appear during the run', livePoints > 20, `${livePoints} points`);
  check('a running E2 with its interval is shown before the final one', sawRunningFit);
  const e2 = await page.textContent('#e2');
  const m = /E2 = ([\d.]+) kPa \(95 % CI ([\d.]+) \.\. ([\d.]+) kPa\)/.exec(e2);
  const job = await apiGet(`/v1/experiments/${jobId}`);
  check('the final E2 is shown and matches the job', m && job.state === 'complete' && job.fit
    && Math.abs(Number(m[1]) - job.fit.modulus_kpa) < 0.051, `${e2}; job ${job.state}`);
  // The simulated sample is the paper's gelatin at 200 kPa; the demo's error is within 2 %.
  check('the estimate is near the simulated 200 kPa', m && Math.abs(Number(m[1]) - 200) < 10, e2);
  const maxEvents = Math.max(...perf.events);
  const drawRates = perf.draws.filter((d) => d > 0);
  const medianDraws = drawRates.sort((a, b) => a - b)[Math.floor(drawRates.length / 2)] || 0;
  const lagged = Number(await page.textContent('#v-lagged'));
  const shown = Number(await page.textContent('#points-count'));
  const kept = (await apiGet('/v1/live')).points.length;
  // Keeping up: the daemon dropped no event for the page (it would send `lagged`), every
  // paired point reached the plot, and the page redrew at least 5 times a second (it
  // draws once per animation frame while events arrive: 20-60/s unloaded; 5/s still
  // follows the run within 0.2 s on a starved machine). The event rate is reported: about
  // 100 sample events/s (2 kHz decimated by the daemon) + 60 frames/s + points unloaded,
  // less when the simulated bench itself falls behind the wall clock.
  check('the page keeps up with the 2 kHz stream and 60 frames/s', lagged === 0 && shown === kept && medianDraws >= 5,
    `up to ${maxEvents} events/s, median ${medianDraws} draws/s, ${lagged} events lagged, ${shown} of ${kept} points shown`);
  if (SCREENSHOT) {
    await page.click('#record-list li a');
    await page.waitForSelector('#record-detail img');
    await sleep(500);
    await page.evaluate(() => window.scrollTo(0, 0));
    await page.screenshot({ path: SCREENSHOT });
    console.log(`# screenshot: ${SCREENSHOT}`);
  }
  // The record with its plots and files.
  await page.click('#record-list li a');
  await page.waitForSelector('#record-detail .record-fit');
  // The file list follows the plots, which load one by one: wait for it (the plots of a
  // record are a few SVGs of tens of kB; 20 s covers a starved machine).
  await page.waitForSelector('#record-detail ul.list a', { timeout: 20000 }).catch(() => {});
  const links = await page.$$eval('#record-detail a', (as) => as.map((a) => a.textContent));
  check('the record shows its fit and downloadable files', ['fit.json', 'curve.csv', 'meta.json'].every((f) => links.includes(f)),
    links.join(' '));

  // --- an experiment at the automatic pressure ----------------------------------------
  // (the simulated 200 kPa gelatin: the 6 kPa probe moves it to a higher calibrated one)
  await page.check('#pressure-auto');
  await page.fill('input[name=repeats]', '1');
  await page.click('#submit-experiment');
  const autoId = Number(await until('automatic-pressure experiment queued', async () => {
    const id = await page.getAttribute('#form-result', 'data-job');
    return Number(id) > jobId && id;
  }, UI_MS));
  const autoJob = await until('automatic-pressure experiment done', async () => {
    const j = await apiGet(`/v1/experiments/${autoId}`);
    return ['complete', 'partial', 'failed', 'cancelled'].includes(j.state) && j;
  }, JOB_MS);
  const chosen = autoJob.pressure_choice && autoJob.pressure_choice.chosen_kpa;
  const autoLine = await until('the job line shows the choice', async () => {
    const li = await page.$(`#jobs li[data-job="${autoId}"][data-chosen-kpa="${chosen}"]`);
    return li && li.textContent();
  }, UI_MS).catch(() => '');
  check('an automatic-pressure job shows the probe and the chosen pressure',
    autoJob.state === 'complete' && chosen > 6 && autoJob.fit && autoJob.fit.p_air_kpa === chosen
      && autoLine.includes(`auto: ${chosen} kPa`) && autoLine.includes('probe at 6 kPa'),
    `${autoJob.state} ${autoJob.message} | ${autoLine}`);
  await until('its record listed first', async () =>
    (await page.textContent('#record-list li a')) === autoJob.record, UI_MS).catch(() => {});
  await page.click('#record-list li a'); // the newest record first
  const recordChoice = await page.waitForSelector('#record-detail .record-pressure')
    .then((e) => e.getAttribute('data-chosen-kpa')).catch(() => null);
  check('its record shows the chosen pressure', Number(recordChoice) === chosen, `${recordChoice}`);
  await page.uncheck('#pressure-auto');

  // --- the stop button mid-run -------------------------------------------------------
  await page.fill('input[name=repeats]', '6');
  await page.click('#submit-experiment');
  const stopId = Number(await until('second experiment queued', async () => {
    const id = await page.getAttribute('#form-result', 'data-job');
    return Number(id) > autoId && id;
  }, UI_MS));
  await until('second experiment producing points', async () => {
    const j = await apiGet(`/v1/experiments/${stopId}`);
    const pts = Number(await page.textContent('#points-count'));
    return j.state === 'running' && pts > 10;
  }, JOB_MS);
  // A third one waits in the queue; its Cancel button takes it out.
  await page.fill('input[name=label]', 'to be cancelled');
  await page.click('#submit-experiment');
  const queuedId = Number(await until('third experiment queued', async () => {
    const id = await page.getAttribute('#form-result', 'data-job');
    return Number(id) > stopId && id;
  }, UI_MS));
  await page.click(`#jobs li[data-job="${queuedId}"] button.cancel`);
  const cancelled = await until('queued job cancelled', async () => {
    const j = await apiGet(`/v1/experiments/${queuedId}`);
    return j.state !== 'queued' && j;
  }, UI_MS);
  check('a queued job is cancelled from the page', cancelled.state === 'cancelled', cancelled.state);
  const stopsBefore = (await apiGet('/v1/status')).emergency_stops;
  const tStop = Date.now();
  await page.click('#estop');
  await page.waitForSelector('#stop-result[data-outcome]');
  const outcome = await page.getAttribute('#stop-result', 'data-outcome');
  const stopMs = Date.now() - tStop;
  const stopped = await until('stopped job ended', async () => {
    const j = await apiGet(`/v1/experiments/${stopId}`);
    return j.state !== 'running' && j.state !== 'queued' && j;
  }, JOB_MS);
  // The status report is refreshed by the device thread's next poll after the link is
  // reopened: wait for it (about 0.1-0.5 s unloaded), then read the vent and the setpoint.
  let st = null;
  try {
    st = await until('vent open and pressure off in the status', async () => {
      st = await apiGet('/v1/status');
      return st.connected && st.vent_open === true && st.setpoint_kpa === 0 && st;
    }, CONNECT_MS);
  } catch (e) {
    console.log(`# ${e.message}: ${JSON.stringify(st && { connected: st.connected, vent_open: st.vent_open, setpoint_kpa: st.setpoint_kpa })}`);
  }
  st = st || { vent_open: null, emergency_stops: null };
  // `sent` (frames written, acknowledgement not within the daemon's 2 s) is accepted only
  // together with the vent read back open: on a starved machine the simulated controller
  // may answer late, and the vent is what matters.
  check('the stop button stops: vent open, job partial',
    (outcome === 'acknowledged' || outcome === 'sent') && st.vent_open === true && stopped.state === 'partial'
      && st.emergency_stops === stopsBefore + 1,
    `outcome ${outcome} in ${stopMs} ms, vent_open ${st.vent_open}, job ${stopped.state}`);

  // --- a page of another origin -------------------------------------------------------
  const foreign = createServer((req, res) => {
    res.writeHead(200, { 'Content-Type': 'text/html' });
    res.end('<!doctype html><title>elsewhere</title><p>another site</p>');
  });
  await new Promise((r) => foreign.listen(0, '127.0.0.1', r));
  const fport = foreign.address().port;
  const fpage = await browser.newPage();
  await fpage.goto(`http://127.0.0.1:${fport}/`);
  const jobsBefore = (await apiGet('/v1/experiments')).length;
  const stopsBefore2 = (await apiGet('/v1/status')).emergency_stops;
  const recordName = (await apiGet('/v1/records'))[0].name;
  const attempts = await fpage.evaluate(async ([daemonBase, record]) => {
    const out = {};
    // An image of the daemon's embedded in another site's page: the cookie is sent, but
    // the browser marks the request same-site, not same-origin.
    out.image = await new Promise((done) => {
      const img = new Image();
      img.onload = () => done('loaded');
      img.onerror = () => done('refused');
      img.src = `${daemonBase}/v1/records/${record}/a_us.svg`;
    });
    // A "simple" request: no preflight, the browser sends the cookie (same site: only the
    // port differs) and its own Origin.
    try {
      await fetch(`${daemonBase}/v1/stop`, { method: 'POST', mode: 'no-cors', credentials: 'include' });
      out.noCors = 'sent';
    } catch (e) { out.noCors = `blocked: ${e}`; }
    try {
      const r = await fetch(`${daemonBase}/v1/experiments`, {
        method: 'POST', credentials: 'include',
        headers: { 'Content-Type': 'application/json', 'X-Tactile-CSRF': 'guess' },
        body: JSON.stringify({ pressure_kpa: 6 }),
      });
      out.cors = `answered ${r.status}`;
    } catch (e) { out.cors = 'blocked'; }
    try {
      const r = await fetch(`${daemonBase}/v1/status`, { credentials: 'include' });
      out.read = `read ${r.status}`;
    } catch (e) { out.read = 'blocked'; }
    return out;
  }, [base, recordName]);
  const formNav = fpage.waitForNavigation();
  await fpage.evaluate((daemonBase) => {
    const f = document.createElement('form');
    f.method = 'POST'; f.action = `${daemonBase}/v1/experiments`; f.enctype = 'text/plain';
    const i = document.createElement('input');
    i.name = '{"pressure_kpa":6,"label":"'; i.value = '"}';
    f.appendChild(i); document.body.appendChild(f); f.submit();
  }, base);
  const formResponse = await formNav;
  await sleep(500);
  const jobsAfter = (await apiGet('/v1/experiments')).length;
  const stopsAfter = (await apiGet('/v1/status')).emergency_stops;
  check('a page on another port cannot stop, queue, read or embed', attempts.cors === 'blocked' && attempts.read === 'blocked'
    && attempts.image === 'refused'
    && formResponse && formResponse.status() === 403 && jobsAfter === jobsBefore && stopsAfter === stopsBefore2,
    `${JSON.stringify(attempts)}, form ${formResponse && formResponse.status()}, jobs ${jobsBefore}->${jobsAfter}, stops ${stopsBefore2}->${stopsAfter}`);
  await fpage.close();
  foreign.close();

  // --- the daemon restarts -----------------------------------------------------------
  // The new simulated bench has a pressure spike (30 kPa over the 20 kPa limit for 50 ms)
  // 3 s after it starts: the controller latches OVERPRESSURE and vents; the cause is gone
  // at once, so the fault can be cleared.
  const scenario = join(dir, 'overpressure.toml');
  writeFileSync(scenario, 'name = "overpressure"\n[faults]\noverpressure = { at_s = 3.0, rise_kpa = 30.0, duration_s = 0.05 }\n');
  const addr = daemon.addr;
  const tDown = Date.now();
  await stopDaemon(daemon.child);
  await page.waitForSelector('body[data-feed="down"]');
  daemon = await startDaemon(addr, ['--scenario', scenario]);
  await page.waitForSelector('body[data-feed="live"]', { timeout: CONNECT_MS });
  await until('page shows the device again', async () =>
    (await page.textContent('#link-state')).startsWith('device: /'), CONNECT_MS);
  check('the page reconnects after a daemon restart without a new login', true, `${Date.now() - tDown} ms`);

  // --- the fault banner ----------------------------------------------------------------
  await page.waitForSelector('#fault-banner:not([hidden])', { timeout: CONNECT_MS });
  const faultText = await page.textContent('#fault-names');
  await page.click('#clear-fault');
  await page.waitForSelector('#fault-banner', { state: 'hidden', timeout: CONNECT_MS });
  const faultsAfter = (await apiGet('/v1/status')).faults;
  check('the fault banner shows the latched fault and Clear fault clears it',
    faultText.includes('OVERPRESSURE') && faultsAfter.length === 0, `${faultText}; after: ${JSON.stringify(faultsAfter)}`);

  check('no script errors in the page', pageErrors.length === 0, pageErrors.slice(0, 3).join(' | '));
}

const started = Date.now();
try {
  await main();
} catch (e) {
  check('the run completed', false, String(e && e.stack || e));
  if (daemonLog) console.log(`# daemon log (last lines):\n${daemonLog.split('\n').slice(-15).map((l) => `# ${l}`).join('\n')}`);
} finally {
  if (daemon) await stopDaemon(daemon.child);
  rmSync(dir, { recursive: true, force: true });
}
const failed = results.filter((r) => !r.ok).length;
console.log(`# browser tier took ${((Date.now() - started) / 1000).toFixed(1)} s`);
console.log(`${results.length - failed} passed, ${failed} failed`);
process.exit(failed ? 1 : 0);
