// The run's time plots (uPlot): tracking error, wheel speed vs command, bus.
// Data are appended per sample (cheap); the charts are redrawn only by flush() (the caller
// throttles it). setTime(t) moves the cursor and a time marker on every chart.
import uPlot from 'uplot';

const WHEEL_COLOURS = ['#ef5350', '#66bb6a', '#42a5f5', '#ffca28'];
// tick labels with as many decimals as the tick spacing needs (0.0025 -> 4), never "-0"
function tickValues(u, splits) {
  if (!splits || !splits.length) return splits;
  const inc = splits.length > 1 ? Math.abs(splits[1] - splits[0]) : Math.abs(splits[0]) || 1;
  if (inc > 0 && inc < 1e-4) return splits.map((v) => (v == null ? '' : v === 0 ? '0' : v.toExponential(1)));
  let d = 0;
  while (d < 8 && Math.abs(Math.round(inc * 10 ** d) - inc * 10 ** d) > 1e-6 * 10 ** d) d++;
  return splits.map((v) => {
    if (v == null) return '';
    const txt = v.toFixed(d);
    return /^-0(\.0*)?$/.test(txt) ? txt.slice(1) : txt;
  });
}
function tickSize(u, values, axisIdx, cycleNum) {
  const axis = u.axes[axisIdx];
  if (cycleNum > 1) return axis._size;
  const n = values && values.length ? Math.max(...values.map((v) => String(v).length)) : 3;
  return Math.ceil(n * 6.6 + 16);
}
const AXIS = { stroke: '#8a93a3', grid: { stroke: '#2a303b', width: 1 }, ticks: { stroke: '#2a303b', width: 1 }, values: tickValues };
const YAXIS = { ...AXIS, size: tickSize, labelSize: 14, labelGap: 0 };
const fin = (v) => typeof v === 'number' && Number.isFinite(v);
const diff = (a, b) => (fin(a) && fin(b) ? a - b : null);
const num = (v) => (fin(v) ? v : null);

function fmt(v, digits) {
  if (v == null || !Number.isFinite(v)) return '–';
  const txt = v.toFixed(digits);
  return /^-0(\.0*)?$/.test(txt) ? txt.slice(1) : txt;
}

// column extractors: one per data column (column 0 is t)
const COLUMNS = [
  (s) => s.t,
  (s) => diff(s.x, s.ref_x),
  (s) => diff(s.y, s.ref_y),
  (s) => diff(s.phi, s.ref_phi),
  ...[0, 1, 2, 3].flatMap((i) => [
    (s) => num(s.wheels && s.wheels[i] && s.wheels[i].speed),
    (s) => num(s.wheels && s.wheels[i] && s.wheels[i].cmd),
  ]),
  (s) => (s.bus && fin(s.bus.load) ? s.bus.load * 100 : null),
  (s) => num(s.bus && s.bus.errors),
  (s) => num(s.bus && s.bus.dropouts),
  (s) => num(s.faults),
];
const C = { t: 0, ex: 1, ey: 2, ephi: 3, w: 4, load: 12, errors: 13, dropouts: 14, faults: 15 };

function specs() {
  const x = { label: 't', value: (u, v) => (v == null ? '–' : `${v.toFixed(2)} s`) };
  return [
    {
      id: 'plot-error', title: 'Tracking error (actual − reference)',
      cols: [C.t, C.ex, C.ey, C.ephi],
      series: [x,
        { label: 'x [m]', stroke: '#4fc3f7', width: 1.5, scale: 'm', value: (u, v) => fmt(v, 4) },
        { label: 'y [m]', stroke: '#ba68c8', width: 1.5, scale: 'm', value: (u, v) => fmt(v, 4) },
        { label: 'φ [rad]', stroke: '#ffb74d', width: 1.2, scale: 'rad', value: (u, v) => fmt(v, 4) }],
      axes: [{ ...AXIS }, { ...YAXIS, scale: 'm', label: 'm' },
        { ...YAXIS, scale: 'rad', side: 1, label: 'rad', grid: { show: false } }],
    },
    {
      id: 'plot-wheels', title: 'Wheel speed (solid) vs command (dashed) [rad/s]',
      cols: [C.t, ...[0, 1, 2, 3].flatMap((i) => [C.w + 2 * i, C.w + 2 * i + 1])],
      series: [x, ...[0, 1, 2, 3].flatMap((i) => [
        { label: `W${i + 1}`, stroke: WHEEL_COLOURS[i], width: 1.5, scale: 'w', value: (u, v) => fmt(v, 2) },
        { label: `W${i + 1} cmd`, stroke: WHEEL_COLOURS[i], width: 1, dash: [5, 4], scale: 'w', value: (u, v) => fmt(v, 2) },
      ])],
      axes: [{ ...AXIS }, { ...YAXIS, scale: 'w', label: 'rad/s' }],
    },
    {
      id: 'plot-bus', title: 'Bus load and errors',
      cols: [C.t, C.load, C.errors, C.dropouts, C.faults],
      series: [x,
        { label: 'load [%]', stroke: '#4fc3f7', width: 1.5, scale: '%', fill: '#4fc3f718', value: (u, v) => fmt(v, 2) },
        { label: 'errors', stroke: '#ef5350', width: 1.5, scale: 'n', value: (u, v) => fmt(v, 0) },
        { label: 'dropouts', stroke: '#ffca28', width: 1.5, scale: 'n', value: (u, v) => fmt(v, 0) },
        { label: 'faults', stroke: '#ba68c8', width: 1, dash: [4, 3], scale: 'n', value: (u, v) => fmt(v, 0) }],
      axes: [{ ...AXIS }, { ...YAXIS, scale: '%', label: '%' },
        { ...YAXIS, scale: 'n', side: 1, label: 'count', grid: { show: false }, incrs: [1, 2, 5, 10, 20, 50, 100, 200, 500, 1e3, 2e3, 5e3, 1e4, 1e5, 1e6, 1e7] }],
      scales: { '%': { range: (u, min, max) => [0, Math.max(1, max * 1.1)] }, n: { range: (u, min, max) => [0, Math.max(1, max + 1)] } },
    },
  ];
}

export class Plots {
  // container: #plots; onPick(t): a click on a chart (used for seeking in scrub mode)
  constructor(container, { onPick } = {}) {
    this.container = container;
    this.cols = COLUMNS.map(() => []);
    this.marker = null;
    this.charts = [];
    this.onPick = onPick || null;
    this.flushes = 0;
    for (const spec of specs()) this._create(spec);
    this._ro = new ResizeObserver(() => this._resize());
    for (const c of this.charts) this._ro.observe(c.body);
  }

  _create(spec) {
    const box = document.createElement('div');
    box.className = 'plot';
    box.id = spec.id;
    const title = document.createElement('div');
    title.className = 'plot-title';
    title.textContent = spec.title;
    const body = document.createElement('div');
    body.className = 'plot-body';
    box.append(title, body);
    this.container.append(box);
    const self = this;
    const opts = {
      width: Math.max(100, body.clientWidth || 300),
      height: Math.max(60, body.clientHeight || 150),
      series: spec.series,
      axes: spec.axes,
      scales: { x: { time: false }, ...(spec.scales || {}) },
      legend: { show: true, live: true },
      cursor: { sync: { key: 'omnitwin', setSeries: false }, drag: { x: true, y: false }, y: false, points: { size: 5 } },
      hooks: {
        draw: [(u) => self._drawMarker(u)],
      },
    };
    const u = new uPlot(opts, spec.cols.map(() => []), body);
    u.over.addEventListener('click', (e) => {
      if (!this.onPick || u.select.width > 2) return;
      const t = u.posToVal(e.offsetX, 'x');
      if (Number.isFinite(t)) this.onPick(t);
    });
    this.charts.push({ spec, u, body, box });
  }

  _drawMarker(u) {
    if (this.marker == null) return;
    const x = u.valToPos(this.marker, 'x', true);
    if (!Number.isFinite(x) || x < u.bbox.left - 1 || x > u.bbox.left + u.bbox.width + 1) return;
    const ctx = u.ctx;
    ctx.save();
    ctx.strokeStyle = 'rgba(255,255,255,0.75)';
    ctx.lineWidth = Math.max(1, window.devicePixelRatio || 1);
    ctx.beginPath();
    ctx.moveTo(Math.round(x) + 0.5, u.bbox.top);
    ctx.lineTo(Math.round(x) + 0.5, u.bbox.top + u.bbox.height);
    ctx.stroke();
    ctx.restore();
  }

  _resize() {
    for (const c of this.charts) {
      const legend = c.u.root.querySelector('.u-legend');
      const lh = legend ? legend.offsetHeight : 0;
      c.legendHeight = lh;
      const w = Math.max(100, Math.floor(c.body.clientWidth));
      const h = Math.max(50, Math.floor(c.body.clientHeight - lh - 2));
      if (w !== c.u.width || h !== c.u.height) c.u.setSize({ width: w, height: h });
    }
  }

  get length() { return this.cols[0].length; }

  clear() { for (const c of this.cols) c.length = 0; }

  append(samples) {
    for (const s of samples) for (let k = 0; k < COLUMNS.length; k++) this.cols[k].push(COLUMNS[k](s));
  }

  setAll(samples) { this.clear(); this.append(samples); this.flush(); }

  // Hand the data so far to the charts and redraw them.
  flush() {
    for (const c of this.charts) c.u.setData(c.spec.cols.map((k) => this.cols[k].slice()));
    this.flushes++;
    this._resize();
    if (this.marker != null) this._placeCursors(this.marker);
  }

  // Time marker and cursor at t on every chart (null: none).
  setTime(t) {
    this.marker = Number.isFinite(t) ? t : null;
    for (const c of this.charts) c.u.redraw(false, false);
    if (this.marker != null) this._placeCursors(this.marker);
    // the legend's values may wrap to another line: keep the chart inside its box
    if (this.charts.some((c) => { const l = c.u.root.querySelector('.u-legend'); return l && l.offsetHeight !== c.legendHeight; })) this._resize();
  }

  _placeCursors(t) {
    for (const c of this.charts) {
      const u = c.u;
      if (!u.data[0] || !u.data[0].length) continue;
      const left = u.valToPos(t, 'x');
      if (!Number.isFinite(left)) continue;
      u.setCursor({ left, top: Math.max(0, u.bbox.height / (window.devicePixelRatio || 1) / 2) }, false, false);
    }
  }

  // the x value at each chart's cursor (for tests)
  cursorTimes() {
    return this.charts.map((c) => (c.u.cursor.idx != null ? c.u.data[0][c.u.cursor.idx] : null));
  }
}
