// A small canvas plot of numeric series over time: the last WINDOW_S seconds, at
// most MAX_POINTS points a series (older ones are dropped as new ones come).

export const WINDOW_S = 30;
export const MAX_POINTS = 2000;
export const COLOURS = ['#2b7bd6', '#d6472b', '#2ba84a', '#a02bd6', '#d6a02b', '#2bc4d6'];

export class Plot {
  // legend: whether the canvas names its series (false when the page lists them)
  constructor(canvas, { legend = true } = {}) {
    this.canvas = canvas;
    this.legend = legend;
    this.series = new Map(); // name -> [[t, value], ...]
    this.colours = new Map(); // name -> its colour, when set (else by its place)
    this.frame = 0;
  }

  add(name, value, t = performance.now() / 1000) {
    if (!Number.isFinite(value)) return;
    let points = this.series.get(name);
    if (!points) {
      points = [];
      this.series.set(name, points);
    }
    points.push([t, value]);
    while (points.length > MAX_POINTS || (points.length && points[0][0] < t - WINDOW_S)) points.shift();
    if (!this.frame) this.frame = requestAnimationFrame(() => this.draw());
  }

  clear() {
    this.series.clear();
    this.draw();
  }

  remove(name) {
    this.series.delete(name);
    this.colours.delete(name);
    this.draw();
  }

  draw() {
    this.frame = 0;
    const { canvas } = this;
    const ctx = canvas.getContext('2d');
    const width = canvas.width;
    const height = canvas.height;
    ctx.clearRect(0, 0, width, height);
    let lo = Infinity;
    let hi = -Infinity;
    let t0 = Infinity;
    let t1 = -Infinity;
    for (const points of this.series.values()) {
      for (const [t, v] of points) {
        lo = Math.min(lo, v);
        hi = Math.max(hi, v);
        t0 = Math.min(t0, t);
        t1 = Math.max(t1, t);
      }
    }
    if (!Number.isFinite(lo)) return;
    if (hi === lo) {
      hi += 1;
      lo -= 1;
    }
    // the last WINDOW_S seconds, or all the data while there is less of it
    t0 = Math.max(t0, t1 - WINDOW_S);
    const span = Math.max(t1 - t0, 1e-3);
    const x = (t) => ((t - t0) / span) * (width - 50) + 45;
    const y = (v) => height - 15 - ((v - lo) / (hi - lo)) * (height - 30);
    ctx.fillStyle = '#666';
    ctx.font = '11px sans-serif';
    ctx.fillText(hi.toPrecision(4), 2, 12);
    ctx.fillText(lo.toPrecision(4), 2, height - 4);
    ctx.fillText(`${span.toFixed(1)} s`, width - 45, height - 4);
    let index = 0;
    for (const [name, points] of this.series) {
      ctx.strokeStyle = this.colours.get(name) ?? COLOURS[index % COLOURS.length];
      ctx.beginPath();
      points.forEach(([t, v], i) => (i ? ctx.lineTo(x(t), y(v)) : ctx.moveTo(x(t), y(v))));
      ctx.stroke();
      ctx.fillStyle = ctx.strokeStyle;
      if (this.legend) ctx.fillText(name, 50 + index * 110, 12);
      index += 1;
    }
  }
}

// The numeric leaves of a message, as [dotted path, value] (arrays' first items only).
export function numericFields(value, path = '', out = [], depth = 0) {
  if (typeof value === 'number') out.push([path, value]);
  else if (value && typeof value === 'object' && depth < 6) {
    const entries = Array.isArray(value) ? value.slice(0, 4).map((v, i) => [i, v]) : Object.entries(value);
    for (const [k, v] of entries) numericFields(v, path ? `${path}.${k}` : String(k), out, depth + 1);
  }
  return out;
}
