// omnitwin run view: the live (Server-Sent Events) or recorded (/api/run) view of one run.
// Live: the display follows the newest sample (pause freezes it while data keep coming);
// after the run's end, and in recorded mode, a timeline scrubs the history (and the video).
import { Scene3D } from './scene3d.js';
import { Plots } from './plots.js';

const $ = (sel) => document.querySelector(sel);
const fin = (v) => typeof v === 'number' && Number.isFinite(v);
const PLOT_INTERVAL_MS = 250;              // live plots: at most 4 redraws per second

const state = {
  info: null,
  mode: null,                              // 'live' | 'recorded'
  samples: [],                             // the history (all samples received, in order)
  lastSeq: -Infinity,
  lastT: -Infinity,
  events: [],
  end: null,
  started: false,
  ended: false,
  paused: false,                           // live: display frozen
  scrub: false,                            // timeline mode (recorded, or live after end)
  playing: false,
  speed: 1,
  displayT: null,                          // the sim time on display
  displayed: null,                         // the (interpolated) sample on display
  shownCount: 0,                           // live: samples shown in the paths
  statusHistory: [],
  errors: [],
};
let scene = null;
let plots = null;
let video = null;
let es = null;

// ---------------------------------------------------------------- the test / automation hook
window.omnitwinView = {
  get samples() { return state.samples.length; },
  get frames() { return scene ? scene.frames : 0; },
  get lastSample() { return state.samples.length ? state.samples[state.samples.length - 1] : null; },
  get mode() { return state.mode; },
  get ended() { return state.ended; },
  get paused() { return state.paused; },
  get playing() { return state.playing; },
  get scrub() { return state.scrub; },
  get time() { return state.displayT; },
  get displayed() { return state.displayed; },
  get history() { return state.samples; },
  get events() { return state.events; },
  get end() { return state.end; },
  get info() { return state.info; },
  get statusHistory() { return state.statusHistory.slice(); },
  get plotFlushes() { return plots ? plots.flushes : 0; },
  get sceneReady() { return !!scene; },
  cursorTimes() { return plots ? plots.cursorTimes() : []; },
  seek(t) { return seek(Number(t)); },
  play() { play(); },
  pause() { if (state.scrub) stopPlaying(); else setPaused(true); },
};

// ---------------------------------------------------------------- formatting
function fmt(v, digits) {
  if (!fin(v)) return '–';
  const txt = v.toFixed(digits);
  return /^-0(\.0*)?$/.test(txt) ? txt.slice(1) : txt;      // no "-0.000"
}
function fmtInt(v) { return fin(v) ? String(Math.round(v)) : '–'; }
function setText(el, text) { if (el && el.textContent !== text) el.textContent = text; }
const round6 = (v) => (fin(v) ? String(Math.round(v * 1e6) / 1e6) : '');

// ---------------------------------------------------------------- header / status
function applyInfo(info) {
  if (!info || typeof info !== 'object') return;
  state.info = { ...(state.info || {}), ...info };
  const i = state.info;
  if (!state.mode && (i.mode === 'live' || i.mode === 'recorded')) state.mode = i.mode;
  setText($('#mode'), state.mode || '');
  setText($('#scenario'), i.scenario || '–');
  setText($('#bus-name'), i.bus || '–');
  setText($('#clock'), i.clock || '–');
  document.title = `${i.scenario || 'run'} · omnitwin`;
  document.body.dataset.mode = state.mode || '';
  if (state.mode === 'live' && !state.ended) {
    if (i.started === true) { state.started = true; setRunStatus('running'); } else if (!state.started) setRunStatus('waiting');
  }
  updateTimelineRange();
}

function setRunStatus(key) {
  const text = key === 'passed' ? 'ended: passed' : key === 'failed' ? 'ended: failed'
    : key === 'interrupted' ? 'ended: interrupted' : key;
  const el = $('#run-status');
  setText(el, text);
  el.dataset.status = key;
  if (state.statusHistory[state.statusHistory.length - 1] !== text) state.statusHistory.push(text);
}

function endStatus(end) {
  // An interrupted run does not pass, whatever its bounds said (a signal during its video or
  // report left the verdict "passed" in metrics.json, and the page showed it).
  if (end && end.metrics && end.metrics.interrupted === true) return 'interrupted';
  if (end && end.passed === true) return 'passed';
  if (end && end.passed === false) return 'failed';
  return 'ended';
}

function setConn(text) {
  const el = $('#conn');
  el.hidden = !text;
  setText(el, text || '');
}

// ---------------------------------------------------------------- samples in
function addSamples(batch) {
  if (!Array.isArray(batch)) return [];
  const added = [];
  for (const s of batch) {
    if (!s || typeof s !== 'object') continue;
    if (fin(s.seq)) {                            // a replay after a reconnect: skip what we hold
      if (s.seq <= state.lastSeq) continue;
      state.lastSeq = s.seq;
    } else if (fin(s.t) && s.t < state.lastT) continue;
    if (fin(s.t)) state.lastT = s.t;
    state.samples.push(s);
    added.push(s);
  }
  if (added.length && plots) plots.append(added);
  return added;
}

function addEvents(list) {
  if (!Array.isArray(list) || !list.length) return;
  const ul = $('#events');
  const atBottom = ul.scrollHeight - ul.scrollTop - ul.clientHeight < 24;
  const frag = document.createDocumentFragment();
  for (const e of list) {
    if (!e || typeof e !== 'object') continue;
    const idx = state.events.length;
    state.events.push(e);
    const li = document.createElement('li');
    const kind = String(e.kind || 'info');
    li.dataset.kind = kind;
    li.dataset.index = String(idx);
    if (fin(e.t)) li.dataset.t = String(e.t);
    const t = document.createElement('span'); t.className = 't'; t.textContent = fmt(e.t, 3);
    const k = document.createElement('span'); k.className = 'kind'; k.textContent = kind;
    const tx = document.createElement('span'); tx.className = 'text';
    const src = document.createElement('span'); src.className = 'src'; src.textContent = e.source || '';
    tx.append(src, document.createTextNode(e.text || ''));
    li.append(t, k, tx);
    if (state.scrub && fin(e.t) && fin(state.displayT) && e.t > state.displayT + 1e-9) li.classList.add('future');
    frag.append(li);
  }
  ul.append(frag);
  if (atBottom || !state.scrub) ul.scrollTop = ul.scrollHeight;
}

// ---------------------------------------------------------------- the display
function indexAt(t) {                          // last sample with s.t <= t (0 if before all)
  const s = state.samples;
  const n = s.length;
  if (!n) return -1;
  if (!(t > s[0].t)) return 0;
  if (t >= s[n - 1].t) return n - 1;
  let lo = 0, hi = n - 1;
  while (hi - lo > 1) {
    const mid = (lo + hi) >> 1;
    if (s[mid].t <= t) lo = mid; else hi = mid;
  }
  return lo;
}

function wrapPi(a) { return a - 2 * Math.PI * Math.round(a / (2 * Math.PI)); }
function lerp(a, b, f) { return fin(a) && fin(b) ? a + (b - a) * f : (fin(a) ? a : b); }
function lerpAngle(a, b, f) { return fin(a) && fin(b) ? a + wrapPi(b - a) * f : (fin(a) ? a : b); }

// The sample at time t: the pose interpolated between neighbours; the discrete state
// (drives, bus, counters) of the last sample at or before t.
function sampleAt(t) {
  const i = indexAt(t);
  if (i < 0) return null;
  const a = state.samples[i];
  const b = state.samples[i + 1];
  if (!b || !(b.t > a.t) || !(t > a.t)) return a;
  const f = Math.min(1, (t - a.t) / (b.t - a.t));
  const s = { ...a, t };
  for (const k of ['x', 'y', 'vx', 'vy', 'wz', 'ref_x', 'ref_y']) s[k] = lerp(a[k], b[k], f);
  s.phi = lerpAngle(a.phi, b.phi, f);
  s.ref_phi = lerpAngle(a.ref_phi, b.ref_phi, f);
  if (Array.isArray(a.wheels) && Array.isArray(b.wheels)) {
    s.wheels = a.wheels.map((w, k) => ({ ...w, angle: lerpAngle(w && w.angle, b.wheels[k] && b.wheels[k].angle, f) }));
  }
  return s;
}

// what the communication layer's state is called on each bus (drives[].comm)
const COMM_LAYER = { ethercat: 'AL', canopen: 'NMT', can: 'slave' };
const driveRows = [1, 2, 3, 4].map((i) => {
  const tr = document.querySelector(`#drives tbody tr[data-index="${i}"]`);
  const proto = document.querySelector(`#drives tbody tr[data-proto="${i}"]`);
  return { node: tr.querySelector('.node'), state: tr.querySelector('.state'), cmd: tr.querySelector('.cmd'), speed: tr.querySelector('.speed'), torque: tr.querySelector('.torque'), proto, words: proto && proto.querySelector('.words') };
});
const busEl = {};
for (const k of ['tx', 'rx', 'errors', 'dropouts', 'load', 'wkc', 'faults']) busEl[k] = document.querySelector(`#bus .${k}`);

function showSample(s, t) {
  state.displayT = t;
  state.displayed = s;
  setText($('#time'), `${fmt(t, 2)} s`);
  if (!s) return;
  const pose = $('#pose');
  pose.dataset.x = round6(s.x);
  pose.dataset.y = round6(s.y);
  pose.dataset.phi = round6(s.phi);
  setText(pose, `x ${fmt(s.x, 3)} m · y ${fmt(s.y, 3)} m · φ ${fin(s.phi) ? fmt(s.phi * 180 / Math.PI, 1) : '–'}°`);

  const drives = Array.isArray(s.drives) ? s.drives : [];
  const wheels = Array.isArray(s.wheels) ? s.wheels : [];
  driveRows.forEach((r, i) => {
    const d = drives[i] || {};
    const w = wheels[i] || {};
    setText(r.node, d.node != null ? String(d.node) : '–');
    const st = d.state != null ? String(d.state) : '–';
    setText(r.state, st);
    if (r.state.dataset.state !== st) r.state.dataset.state = st;
    setText(r.cmd, fmt(fin(d.command) ? d.command : w.cmd, 2));
    setText(r.speed, fmt(w.speed, 2));
    setText(r.torque, fmt(w.torque, 3));
    // the protocol's own words (live runs): EtherCAT AL / CiA 402, CANopen NMT, M-III phase…
    const layer = COMM_LAYER[(state.info && state.info.bus) || ''];
    const comm = typeof d.comm === 'string' && d.comm !== '' && d.comm !== 'off' && layer ? `${layer} ${d.comm}` : d.comm;
    const words = [comm, d.device].filter((x) => typeof x === 'string' && x !== '').join(' · ');
    if (r.proto) {
      if (r.proto.hidden !== !words) r.proto.hidden = !words;
      setText(r.words, words);
    }
    if (r.state.title !== words) r.state.title = words;
  });

  const b = s.bus || {};
  setText($('#bus-kind'), b.has_frames === false ? '(no frames: direct)' : '');
  setText(busEl.tx, fmtInt(b.tx));
  setText(busEl.rx, fmtInt(b.rx));
  setText(busEl.errors, fmtInt(b.errors));
  setText(busEl.dropouts, fmtInt(b.dropouts));
  setText(busEl.load, fin(b.load) ? `${(b.load * 100).toFixed(2)} %` : '–');
  setText(busEl.faults, fmtInt(s.faults));
  setText(busEl.wkc, fmtInt(b.wkc));
  busEl.errors.classList.toggle('nonzero', fin(b.errors) && b.errors > 0);
  busEl.dropouts.classList.toggle('nonzero', fin(b.dropouts) && b.dropouts > 0);
  busEl.faults.classList.toggle('nonzero', fin(s.faults) && s.faults > 0);

  const ex = fin(s.x) && fin(s.ref_x) ? s.x - s.ref_x : null;
  const ey = fin(s.y) && fin(s.ref_y) ? s.y - s.ref_y : null;
  const ephi = fin(s.phi) && fin(s.ref_phi) ? s.phi - s.ref_phi : null;
  setText($('#platform .err-xy'), `${fmt(fin(ex) ? ex * 1000 : null, 1)} / ${fmt(fin(ey) ? ey * 1000 : null, 1)} mm`);
  setText($('#platform .err-phi'), `${fmt(fin(ephi) ? ephi * 180 / Math.PI : null, 3)}°`);
  setText($('#platform .twist'), `${fmt(s.vx, 3)} / ${fmt(s.vy, 3)} m/s`);
  setText($('#platform .wz'), `${fmt(s.wz, 3)} rad/s`);

  if (scene) scene.setSample(s);
}

// ---------------------------------------------------------------- live display loop
let rafId = 0;
let liveDirty = false;
let plotTimer = 0;
let lastPlotFlush = 0;

function schedule() { if (!rafId) rafId = requestAnimationFrame(tick); }

function tick(now) {
  rafId = 0;
  if (state.playing) { playbackStep(now); if (state.playing) schedule(); }
  if (liveDirty && !state.paused && !state.scrub) {
    liveDirty = false;
    const n = state.samples.length;
    if (n) {
      const s = state.samples[n - 1];
      showSample(s, s.t);
      if (scene) { scene.setPaths(state.samples, n); state.shownCount = n; }
    }
  }
}

function schedulePlots() {
  if (!plots || plotTimer || state.paused) return;
  const wait = Math.max(0, PLOT_INTERVAL_MS - (performance.now() - lastPlotFlush));
  plotTimer = setTimeout(() => {
    plotTimer = 0;
    if (state.paused) return;
    lastPlotFlush = performance.now();
    plots.flush();
  }, wait);
}

function onLiveData() {
  if (state.scrub) return;
  if (!state.paused) { liveDirty = true; schedule(); schedulePlots(); }
}

function setPaused(on) {
  if (state.mode === 'recorded' || state.scrub) on = false;   // before /api/info: allowed (live)
  state.paused = !!on;
  const b = $('#pause');
  b.classList.toggle('active', state.paused);
  setText(b, state.paused ? 'Resume' : 'Pause');
  b.title = state.paused ? 'display frozen; data keep being received — resume catches up' : 'freeze the display; data keep being received';
  if (!state.paused) onLiveData();
}

// ---------------------------------------------------------------- live: Server-Sent Events
function startLive() {
  let connections = 0;
  let logSeen = 0;                           // log entries received on this connection
  es = new EventSource('/api/stream');
  es.addEventListener('open', () => {
    connections++;
    logSeen = 0;
    setConn('');
  });
  es.addEventListener('error', () => {
    if (state.ended) { es.close(); return; }
    if (es.readyState === EventSource.CLOSED) setConn('stream closed');
    else setConn('connection lost, retrying…');
  });
  const parse = (ev) => {
    try { return JSON.parse(ev.data); } catch (err) { console.warn('omnitwin view: bad event data', ev.type, err); return null; }
  };
  es.addEventListener('info', (ev) => {
    const info = parse(ev);
    if (!info) return;
    applyInfo({ ...info, started: info.started !== false });
  });
  es.addEventListener('samples', (ev) => {
    const batch = parse(ev);
    if (!batch) return;
    if (!state.started && !state.ended) { state.started = true; setRunStatus('running'); }
    if (addSamples(batch).length) onLiveData();
  });
  es.addEventListener('log', (ev) => {
    const list = parse(ev);
    if (!Array.isArray(list)) return;
    const fresh = list.slice(Math.max(0, state.events.length - logSeen));  // skip a reconnect's replay
    logSeen += list.length;
    addEvents(fresh);
  });
  es.addEventListener('end', (ev) => {
    es.close();                              // the server closes the stream: never reconnect
    const end = parse(ev) || {};
    onEnd(end);
  });
  void connections;
}

function onEnd(end) {
  if (state.ended) return;
  state.ended = true;
  state.end = end;
  setConn('');
  setRunStatus(endStatus(end));
  showVerdict(end);
  const n = state.samples.length;
  const t = state.paused && fin(state.displayT) ? state.displayT : (n ? state.samples[n - 1].t : 0);
  if (plotTimer) { clearTimeout(plotTimer); plotTimer = 0; }
  setPaused(false);
  $('#pause').disabled = true;
  enterScrub(t);
}

// ---------------------------------------------------------------- verdict / metrics
function getPath(o, p) { return p.split('.').reduce((a, k) => (a && typeof a === 'object' ? a[k] : undefined), o); }

function showVerdict(end) {
  const dl = $('#metrics');
  dl.textContent = '';
  const add = (label, value, cls) => {
    const dt = document.createElement('dt'); dt.textContent = label;
    const dd = document.createElement('dd'); dd.textContent = value;
    if (cls) dd.className = cls;
    dl.append(dt, dd);
  };
  const st = endStatus(end);
  if (st === 'interrupted') add('run', 'interrupted', 'bad');
  const ex = end && end.passed === true ? 'passed' : end && end.passed === false ? 'failed' : 'unknown';
  add('expectations', ex, ex === 'passed' ? 'good' : ex === 'failed' ? 'bad' : '');
  if (end && end.exit_code != null) add('exit code', String(end.exit_code), end.exit_code === 0 ? 'good' : 'bad');
  const m = (end && end.metrics) || {};
  const rows = [
    ['final error', 'platform.final_error_cm', 'cm', 2],
    ['max error', 'platform.max_error_cm', 'cm', 2],
    ['final φ error', 'platform.final_phi_error_deg', '°', 3],
    ['bus dropouts', 'bus.dropouts', '', 0],
    ['bus errors', 'bus.errors', '', 0],
    ['lost frames', 'master.lost_frames', '', 0],
    ['sim time', 'sim_time_s', 's', 2],
    ['real-time factor', 'real_time_factor', '×', 1],
  ];
  for (const [label, p, unit, d] of rows) {
    const v = getPath(m, p);
    if (fin(v)) add(label, `${v.toFixed(d)}${unit ? ' ' + unit : ''}`);
  }
  const failures = getPath(m, 'expectations.failures');
  if (Array.isArray(failures)) {
    for (const f of failures) add('failed', typeof f === 'string' ? f : JSON.stringify(f), 'bad');
  }
  $('#verdict').hidden = false;
}

// ---------------------------------------------------------------- scrub mode (timeline, video)
function timeRange() {
  const s = state.samples;
  if (!s.length) return [0, fin(state.info && state.info.duration_s) ? state.info.duration_s : 0];
  return [fin(s[0].t) ? s[0].t : 0, fin(s[s.length - 1].t) ? s[s.length - 1].t : 0];
}

function updateTimelineRange() {
  const tl = $('#timeline');
  const [t0, t1] = timeRange();
  let step = 0.01;
  const s = state.samples;
  if (s.length > 1 && s[1].t > s[0].t) step = Math.min(0.05, s[1].t - s[0].t);
  else if (state.info && fin(state.info.control_period_s) && state.info.control_period_s > 0) step = state.info.control_period_s;
  tl.min = String(t0);
  tl.max = String(Math.max(t1, t0));
  tl.step = 'any';
  tl.dataset.step = String(step);
  if (state.scrub) setText($('#timeline-label'), `${fmt(fin(state.displayT) ? state.displayT : t0, 2)} / ${fmt(t1, 2)} s`);
  else {
    const d = state.info && fin(state.info.duration_s) && state.info.duration_s > 0 ? ` of ${fmt(state.info.duration_s, 0)} s` : '';
    setText($('#timeline-label'), `live${d}`);
  }
}

function enterScrub(t) {
  state.scrub = true;
  if (state.paused) setPaused(false);
  document.body.classList.add('scrub');
  $('#events').classList.add('scrub');
  const tl = $('#timeline');
  tl.disabled = false;
  $('#play').disabled = false;
  if (scene) { scene.setPaths(state.samples, state.samples.length); state.shownCount = state.samples.length; }
  if (plots) plots.flush();
  updateTimelineRange();
  seek(t);
}

// seek(t): the display, the 3D view, the plots' cursors and the video at sim time t.
function seek(t, { fromVideo = false } = {}) {
  if (!state.scrub || !state.samples.length || !Number.isFinite(t)) return null;
  const [t0, t1] = timeRange();
  t = Math.min(t1, Math.max(t0, t));
  const tl = $('#timeline');
  tl.value = String(t);
  showSample(sampleAt(t), t);
  setText($('#timeline-label'), `${fmt(t, 2)} / ${fmt(t1, 2)} s`);
  if (plots) plots.setTime(t);
  markFutureEvents(t);
  if (video && !fromVideo) {
    const d = video.duration;
    video.currentTime = fin(d) && d > 0 ? Math.min(t, d) : t;
  }
  if (state.playing && !video) { playClock.t = t; playClock.wall = performance.now(); }
  return t;
}

let lastFutureT = null;
function markFutureEvents(t) {
  if (lastFutureT === t) return;
  lastFutureT = t;
  for (const li of $('#events').children) {
    const et = Number(li.dataset.t);
    li.classList.toggle('future', Number.isFinite(et) && et > t + 1e-9);
  }
}

const playClock = { t: 0, wall: 0 };
// The sim time playback without a video stands at, at performance.now() == now [s].
function playClockTime(now) { return playClock.t + (now - playClock.wall) / 1000 * state.speed; }
function play() {
  if (!state.scrub || state.playing) return;
  const [t0, t1] = timeRange();
  let t = fin(state.displayT) ? state.displayT : t0;
  if (t >= t1 - 1e-6) t = seek(t0);            // at the end: play from the start
  state.playing = true;
  setText($('#play'), 'Pause');
  $('#play').classList.add('active');
  playClock.t = t;
  playClock.wall = performance.now();
  if (video) {
    video.playbackRate = state.speed;
    const p = video.play();
    if (p && p.catch) p.catch((err) => { console.warn('omnitwin view: the video does not play; playing without it', err && err.message); });
  }
  schedule();
}

function stopPlaying() {
  if (!state.playing) return;
  // Where playback stands now, not at the last animation frame (which a busy machine may have
  // drawn a third of a second ago): the display stops on the frame the video stops on, or at the
  // play clock's time without a video. A video that had already stopped leaves it where it is.
  const videoPlaying = video && !video.paused && !video.ended;
  state.playing = false;
  setText($('#play'), 'Play');
  $('#play').classList.remove('active');
  if (videoPlaying) {
    video.pause();
    seek(video.currentTime, { fromVideo: true });
  } else if (!video) {
    seek(playClockTime(performance.now()));
  }
}

function playbackStep(now) {
  const [, t1] = timeRange();
  let t;
  if (video && !video.paused && !video.ended && video.readyState >= 2) {
    t = video.currentTime;
  } else if (video && !video.paused && !video.ended) {
    return;                                  // the video is buffering: wait for it
  } else {
    t = playClockTime(now);
  }
  if (t >= t1) { seek(t1, { fromVideo: !!video }); stopPlaying(); return; }
  seek(t, { fromVideo: !!video && !video.paused });
}

function setupVideo(url) {
  const box = $('#video-box');
  video = document.createElement('video');
  video.id = 'video';
  video.muted = true;
  video.playsInline = true;
  video.preload = 'auto';
  video.src = url;
  video.title = 'rendered video of the run (video time = sim time)';
  video.addEventListener('ended', () => {
    if (state.playing) { const [, t1] = timeRange(); seek(t1, { fromVideo: true }); stopPlaying(); }
  });
  video.addEventListener('pause', () => { if (state.playing && !video.ended && video.currentTime > 0 && document.visibilityState === 'visible') stopPlaying(); });
  video.addEventListener('loadedmetadata', () => { if (fin(state.displayT)) seek(state.displayT); });
  video.addEventListener('error', () => { console.warn('omnitwin view: the video cannot be loaded', url); });
  box.append(video);
  box.hidden = false;
  $('#video-toggle').hidden = false;
}

// ---------------------------------------------------------------- recorded run
function loadRecorded(run) {
  applyInfo(run.info || {});
  state.mode = 'recorded';
  setText($('#mode'), 'recorded');
  addSamples(Array.isArray(run.samples) ? run.samples : []);
  addEvents(Array.isArray(run.events) ? run.events : []);
  state.ended = true;
  state.end = run.end || null;
  setRunStatus(endStatus(run.end));
  showVerdict(run.end || {});
  $('#pause').hidden = true;
  if (state.info && state.info.video) setupVideo(state.info.video);
  enterScrub(timeRange()[0]);
}

// ---------------------------------------------------------------- controls
function setupControls() {
  $('#pause').addEventListener('click', () => setPaused(!state.paused));
  $('#play').addEventListener('click', () => (state.playing ? stopPlaying() : play()));
  const tl = $('#timeline');
  tl.addEventListener('input', () => seek(Number(tl.value)));
  $('#speed').addEventListener('change', (e) => {
    state.speed = Number(e.target.value) || 1;
    if (video) video.playbackRate = state.speed;
    if (state.playing) { playClock.t = state.displayT; playClock.wall = performance.now(); }
  });
  $('#follow').addEventListener('change', (e) => { if (scene) scene.setFollow(e.target.checked); });
  $('#show-video').addEventListener('change', (e) => { $('#video-box').hidden = !e.target.checked || !video; });
  $('#events').addEventListener('click', (e) => {
    const li = e.target.closest('li');
    if (!li || !state.scrub) return;
    const t = Number(li.dataset.t);
    if (Number.isFinite(t)) seek(t);
  });
  document.addEventListener('keydown', (e) => {
    if (e.target.closest && e.target.closest('input, select, textarea, button')) return;
    if (e.key === ' ') {
      e.preventDefault();
      if (state.scrub) (state.playing ? stopPlaying() : play()); else if (state.mode === 'live') setPaused(!state.paused);
    } else if (state.scrub && (e.key === 'ArrowLeft' || e.key === 'ArrowRight')) {
      e.preventDefault();
      const step = Number($('#timeline').dataset.step) || 0.05;
      seek((state.displayT || 0) + (e.key === 'ArrowRight' ? 1 : -1) * step * (e.shiftKey ? 20 : 1));
    }
  });
}

// ---------------------------------------------------------------- start
async function getJSON(url) {
  const r = await fetch(url, { cache: 'no-store' });
  if (!r.ok) throw new Error(`${url}: HTTP ${r.status}`);
  return r.json();
}

function showMessage(text) {
  const m = $('#view3d-message');
  m.hidden = !text;
  m.textContent = text || '';
}

async function buildScene() {
  let model;
  try {
    model = await getJSON('/api/scene');
  } catch (err) {
    console.warn('omnitwin view: no scene', err.message);
    model = { bodies: [], geoms: [] };
    showMessage('no model (/api/scene unavailable)');
  }
  try {
    scene = new Scene3D($('#view3d'), model);
    scene.setFollow($('#follow').checked);
  } catch (err) {
    showMessage(`3D view unavailable: ${err.message}`);
    throw err;
  }
  // catch up with what arrived meanwhile
  if (state.samples.length) {
    const n = state.scrub ? state.samples.length : (state.shownCount || state.samples.length);
    scene.setPaths(state.samples, n);
    if (state.displayed) scene.setSample(state.displayed);
  }
  scene.requestRender();
}

async function main() {
  setupControls();
  // ?paused: open the live view paused (the data arrive, the display waits for Resume)
  if (new URLSearchParams(location.search).has('paused')) setPaused(true);
  plots = new Plots($('#plots'), { onPick: (t) => { if (state.scrub) seek(t); } });
  const info = await getJSON('/api/info');
  applyInfo(info);
  const scenePromise = buildScene();
  if (state.mode === 'recorded') {
    const run = await getJSON('/api/run');
    loadRecorded(run);
    await scenePromise;
  } else {
    state.mode = 'live';
    setText($('#mode'), 'live');
    $('#timeline').disabled = true;
    $('#play').disabled = true;
    // The 3D view is built and drawn once before the stream opens: with --web-wait the run
    // starts when it opens, and the first frame's shader compilation would compete with it.
    try {
      await scenePromise;
      scene.renderNow();
      await new Promise((r) => requestAnimationFrame(() => r()));
    } catch (err) {
      console.warn('omnitwin view: live without the 3D view', err.message);
    }
    startLive();
  }
}

main().catch((err) => {
  console.error('omnitwin view:', err);
  showMessage(String(err && err.message ? err.message : err));
});
