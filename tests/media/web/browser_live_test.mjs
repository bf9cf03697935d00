#!/usr/bin/env node
// Browser test of omnitwin's live web view: runs a scenario with --web (headless Chromium
// watching it through puppeteer-core) and checks what the page shows while the run goes on
// and after its end.
//
//   node browser_live_test.mjs --omnitwin PATH --scenario FILE --bus NAME --out DIR
//        --artefacts DIR [--timeout S] [-- EXTRA ARGS FOR omnitwin run]
//
// A lockstep run lasts only ~1-3 s of wall time once started (--web-wait starts it when the
// page opens its stream), less than the browser needs to load the page and answer a click.
// So the page is opened paused (URL ?paused, as a click on #pause before any data): the
// display must stay frozen while the samples arrive, and catch up on resume (a click on
// #pause). The screenshot comes right after; the checks that may come after the end (drives
// running, pose moved) are also satisfied from the history the page keeps
// (window.omnitwinView.history). With `-- --clock realtime` the run lasts its simulated
// duration and every check sees it live.
// Exit status 0: passed; 1: a check failed; 2: usage.
import fs from 'node:fs';
import path from 'node:path';

import { harness, sleep, withTimeout } from './browser_support.mjs';

const h = harness('browser_live_test',
  'browser_live_test.mjs --omnitwin PATH --scenario FILE --bus NAME --out DIR --artefacts DIR [--timeout S] [-- EXTRA]',
  ['omnitwin', 'scenario', 'bus', 'out', 'artefacts'], 180);
const { opts, extra, timeoutS, log, check, must, warn } = h;

// ------------------------------------------------------------------ the test
async function main() {
  fs.mkdirSync(opts.artefacts, { recursive: true });
  const shot = path.join(opts.artefacts, `live-${opts.bus}.png`);

  const url = await h.startOmnitwin(['run', opts.scenario, '--bus', opts.bus, '--out', opts.out, '--no-video', '--no-progress',
    '--web', '127.0.0.1:0', '--web-wait', ...extra]);
  log(`web view at ${url}`);

  const { page, errors: pageErrors } = await h.launchBrowser();
  const ms = timeoutS * 1000;
  const text = (sel) => page.$eval(sel, (el) => el.textContent.trim());
  const view = (fn, ...args) => page.evaluate(fn, ...args);

  // --- pause: the page is opened paused (?paused, the same as a click on #pause before any
  // data): with --web-wait the run starts when the page opens its stream, and a lockstep run
  // is over in about a second, sooner than a click could come. The display must stay frozen
  // while the samples arrive, and catch up on resume.
  await page.goto(new URL('?paused', url).href, { waitUntil: 'domcontentloaded', timeout: 60000 });
  await page.waitForFunction(() => window.omnitwinView && document.querySelector('#mode') && document.querySelector('#mode').textContent.trim() !== '', { polling: 10, timeout: 30000 });
  must((await text('#mode')) === 'live', '#mode is "live"', await text('#mode'));
  const p0 = await view(() => ({ time: document.querySelector('#time').textContent, samples: window.omnitwinView.samples, paused: window.omnitwinView.paused, ended: window.omnitwinView.ended, label: document.querySelector('#pause').textContent.trim() }));
  check(p0.paused || p0.ended, 'pause: the view is paused (#pause shows resume)', `button "${p0.label}", #time ${p0.time}, ${p0.samples} samples so far`);
  await page.waitForFunction(() => window.omnitwinView.samples > 0, { polling: 10, timeout: ms });
  await sleep(300);
  const p1 = await view(() => ({ time: document.querySelector('#time').textContent, samples: window.omnitwinView.samples, ended: window.omnitwinView.ended, paused: window.omnitwinView.paused, displayed: window.omnitwinView.displayed !== null }));
  if (!p1.ended) {
    check(p1.time === p0.time && !p1.displayed, 'pause: #time unchanged, nothing shown while paused', `${p0.time} → ${p1.time}`);
    check(p1.samples > 0, 'pause: samples arrived while paused', `${p0.samples} → ${p1.samples}${p1.samples > p0.samples ? '' : ' (all before the first look)'}`);
    await page.click('#pause');
  } else {
    // the end releases the pause: the timeline starts where the display was
    warn(`pause: the run ended within the 300 ms (${p1.samples} samples); the end released the pause`);
    check(!p1.paused, 'pause: released by the run end');
  }
  // Caught up: #time moved on from where the pause held it, or, when the run had already ended
  // at the first look (a loaded machine starts the browser slowly, and the end releases the
  // pause at once), #time shows the newest sample.
  const resumed = await page.waitForFunction((t) => {
    const v = window.omnitwinView;
    const shown = document.querySelector('#time').textContent;
    const atNewest = v.ended && v.lastSample && Math.abs(parseFloat(shown) - v.lastSample.t) < 0.01;
    return !v.paused && (shown !== t || atNewest);
  }, { polling: 10, timeout: 10000 }, p0.time).then(() => true, () => false);
  const r = await view(() => ({ time: document.querySelector('#time').textContent, last: window.omnitwinView.lastSample && window.omnitwinView.lastSample.t, label: document.querySelector('#pause').textContent.trim() }));
  check(resumed, 'resume: the display catches up', `#time ${r.time}, newest sample ${r.last} s, button "${r.label}"`);

  // --- the run goes: status running, samples arrive
  await page.waitForFunction(() => {
    const v = window.omnitwinView;
    const st = document.querySelector('#run-status').textContent.trim();
    return v && v.samples > 0 && (st === 'running' || st.startsWith('ended'));
  }, { polling: 10, timeout: ms });
  const st = await view(() => ({ history: window.omnitwinView.statusHistory, samples: window.omnitwinView.samples }));
  check(st.history.includes('running'), '#run-status went to "running"', `statuses seen: ${st.history.join(' → ')}`);
  check(st.samples > 0, 'omnitwinView.samples > 0', `${st.samples}`);

  // --- the screenshot, as early as possible (once the 3D view has drawn a frame)
  await page.waitForFunction(() => window.omnitwinView.frames > 0, { polling: 10, timeout: 30000 }).catch(() => {});
  const before = await view(() => ({ ended: window.omnitwinView.ended, status: document.querySelector('#run-status').textContent.trim(), time: document.querySelector('#time').textContent }));
  await page.screenshot({ path: shot });
  if (!before.ended) log(`ok    screenshot while ${before.status} at ${before.time}: ${shot}`);
  else warn(`screenshot ${shot} taken after the run ended (the run was faster than the page; -- --clock realtime makes it last)`);
  const pose0 = { x: 0, y: 0 };

  // --- drives reach running (live, or from the page's history if the run was faster)
  const drivesLive = await page.waitForFunction(() => {
    const rows = [...document.querySelectorAll('#drives tbody tr[data-index]')];
    return (rows.length === 4 && rows.every((r) => r.querySelector('.state').textContent.trim() === 'running')) || window.omnitwinView.ended;
  }, { polling: 20, timeout: ms }).then(() => view(() => [...document.querySelectorAll('#drives tbody tr[data-index]')].map((r) => r.querySelector('.state').textContent.trim())));
  if (drivesLive.length === 4 && drivesLive.every((s) => s === 'running')) check(true, 'all four #drives rows show "running"');
  else {
    const seen = await view(() => window.omnitwinView.history.some((s) => Array.isArray(s.drives) && s.drives.length >= 4 && s.drives.slice(0, 4).every((d) => d && d.state === 'running')));
    check(seen, 'all four drives reached "running" (from the history; the run ended first)', `rows now: ${drivesLive.join(', ')}`);
  }
  const rowsOk = await view(() => [1, 2, 3, 4].every((i) => {
    const r = document.querySelector(`#drives tbody tr[data-index="${i}"]`);
    return r && ['.node', '.state', '.cmd', '.speed', '.torque'].every((c) => r.querySelector(c));
  }));
  check(rowsOk, '#drives rows 1..4 have .node .state .cmd .speed .torque');

  // --- the platform moves by more than 1 cm
  Object.assign(pose0, await view(() => { const h = window.omnitwinView.history[0]; return { x: h.x, y: h.y }; }));
  const moved = await page.waitForFunction((p) => {
    const e = document.querySelector('#pose');
    const d = Math.hypot(Number(e.dataset.x) - p.x, Number(e.dataset.y) - p.y);
    return d > 0.01 || window.omnitwinView.ended;
  }, { polling: 20, timeout: ms }, pose0).then(() => view((p) => {
    const e = document.querySelector('#pose');
    const now = Math.hypot(Number(e.dataset.x) - p.x, Number(e.dataset.y) - p.y);
    const hist = window.omnitwinView.history.reduce((m, s) => (Number.isFinite(s.x) && Number.isFinite(s.y) ? Math.max(m, Math.hypot(s.x - p.x, s.y - p.y)) : m), 0);
    return { now, hist };
  }, pose0));
  const poseNow = await view(() => { const e = document.querySelector('#pose'); return { x: e.dataset.x, y: e.dataset.y, phi: e.dataset.phi }; });
  check([poseNow.x, poseNow.y, poseNow.phi].every((v) => v !== '' && Number.isFinite(Number(v))), '#pose has numeric data-x / data-y / data-phi', `${poseNow.x}, ${poseNow.y}, ${poseNow.phi}`);
  check(moved.now > 0.01 || moved.hist > 0.01, 'the platform moved by > 1 cm from its first sample', `#pose ${(moved.now * 100).toFixed(1)} cm, history max ${(moved.hist * 100).toFixed(1)} cm`);

  // --- 3D frames, bus statistics
  const frames = await view(() => window.omnitwinView.frames);
  check(frames > 0, 'the 3D view rendered frames', `${frames}`);
  check(await page.$('#view3d canvas') !== null, '#view3d holds the canvas');
  check(await view(() => document.querySelectorAll('#plots .uplot').length) >= 3, '#plots holds the uPlot charts');
  const tx = await text('#bus .tx');
  check(/^-?\d+(\.\d+)?$/.test(tx), '#bus .tx is a number', tx);

  // --- the end: verdict, the stream closed, scrub mode
  await page.waitForFunction(() => document.querySelector('#run-status').textContent.trim().startsWith('ended'), { polling: 50, timeout: ms });
  const status = await text('#run-status');
  log(`run status: ${status}`);
  const after = await view(() => ({
    ended: window.omnitwinView.ended,
    timeline: !document.querySelector('#timeline').disabled,
    play: !document.querySelector('#play').disabled,
    events: document.querySelectorAll('#events li[data-kind]').length,
    samples: window.omnitwinView.samples,
    lastT: window.omnitwinView.lastSample && window.omnitwinView.lastSample.t,
  }));
  check(after.ended, 'omnitwinView.ended after the end');
  check(after.timeline && after.play, '#timeline and #play enabled after the end (scrub mode)');
  check(after.events > 0, '#events lists the log', `${after.events} entries`);
  log(`samples received: ${after.samples}, last t ${after.lastT}`);

  // scrub after the end: seek to the middle of the history
  const mid = await view(() => {
    const h = window.omnitwinView.history;
    const t = h[0].t + (h[h.length - 1].t - h[0].t) / 2;
    window.omnitwinView.seek(t);
    let best = h[0];
    for (const s of h) if (Math.abs(s.t - t) < Math.abs(best.t - t)) best = s;
    return { t, shown: parseFloat(document.querySelector('#time').textContent), x: Number(document.querySelector('#pose').dataset.x), sx: best.x };
  });
  check(Math.abs(mid.shown - mid.t) < 0.011, 'seek after the end: #time', `${mid.t.toFixed(3)} → "${mid.shown}"`);
  check(Math.abs(mid.x - mid.sx) < 0.02, 'seek after the end: #pose data-x matches the history', `${mid.x} vs ${mid.sx}`);

  // the page must not reconnect: no new stream, no errors while omnitwin exits
  const exit = await withTimeout(h.childExit, 60000, 'omnitwin to exit after the run');
  log(`omnitwin exited: code ${exit.code}, signal ${exit.signal}`);
  await sleep(1500);
  check(exit.code === 0, 'omnitwin exits 0 (expectations passed)', `code ${exit.code}`);
  if (exit.code === 0) check(status === 'ended: passed' || status === 'ended', '#run-status agrees with exit 0', status);
  check(pageErrors.length === 0, 'no page errors and no console errors', pageErrors.slice(0, 5).join(' | '));
}

await h.run(main);
