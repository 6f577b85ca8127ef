// The Plot tab: numeric fields of several topics on one time axis (as PlotJuggler
// or Foxglove's Plot panel), each series a topic and a field path (/odom
// pose.pose.position.x) with its own colour, legend entry and remove button. Time is
// when this page received the message (not the header stamp: not every message has
// one, and the robot's clock may be off from the page's). Pause freezes the plot;
// CSV downloads what it holds: time, then one column per series. Memory is bounded
// by the Plot (the last WINDOW_S seconds, at most MAX_POINTS points a series).
import { COLOURS, Plot } from './plot.js';
import { el } from './ui.js';

const MAX_SERIES = 12;

// The number at a dotted field path (array items by index: ranges.0), or undefined.
export function valueAt(msg, path) {
  let value = msg;
  for (const part of path.split('.')) {
    if (value === null || typeof value !== 'object') return undefined;
    value = value[part];
  }
  return typeof value === 'number' ? value : undefined;
}

function csvCell(text) {
  return /[",\n\r]/.test(text) ? `"${text.replace(/"/g, '""')}"` : text;
}

// columns: [[name, [[t, value], ...]], ...]. One row per time any series has a point
// (in order), its cell empty in the columns that have none then; time in seconds
// since the Unix epoch, to the millisecond.
export function csvText(columns) {
  const rows = new Map(); // time (ms) -> its values, one per column
  columns.forEach(([, points], i) => {
    for (const [t, value] of points) {
      const key = Math.round(t * 1000);
      if (!rows.has(key)) rows.set(key, Array(columns.length).fill(''));
      rows.get(key)[i] = String(value);
    }
  });
  const lines = [['time', ...columns.map(([name]) => name)].map(csvCell).join(',')];
  for (const key of [...rows.keys()].sort((a, b) => a - b)) {
    lines.push([(key / 1000).toFixed(3), ...rows.get(key)].join(','));
  }
  return `${lines.join('\r\n')}\r\n`; // RFC 4180 line ends
}

export class PlotPanel {
  constructor(ros, typeOf) {
    this.ros = ros;
    this.typeOf = typeOf; // topic -> its type in the graph, or undefined
    this.plot = new Plot(document.getElementById('multi-plot'), { legend: false });
    this.series = new Map(); // "topic field" -> {topic, field, item}
    this.unsubscribe = new Map(); // topic -> its unsubscribe function
    this.paused = false;
    this.legend = document.getElementById('plot-legend');
    this.result = document.getElementById('plot-add-result');
    this.download = document.getElementById('plot-download');
    document.getElementById('plot-add').addEventListener('submit', (event) => {
      event.preventDefault();
      const form = event.target;
      if (this.add(form.elements.topic.value.trim(), form.elements.field.value.trim())) form.elements.field.value = '';
    });
    document.getElementById('plot-pause').addEventListener('click', () => this.togglePause());
    document.getElementById('plot-csv').addEventListener('click', () => this.exportCsv());
  }

  // The topics the picker offers (a datalist: any other name may still be typed).
  showTopics(topics) {
    const list = document.getElementById('plot-topics');
    list.replaceChildren(...[...topics].sort().map((topic) => el('option', { value: topic })));
  }

  // Adds a series; returns whether it did (else says why beside the Add button).
  add(topic, field) {
    const name = `${topic} ${field}`;
    const type = this.typeOf(topic);
    let problem = null;
    if (!topic || !field) problem = 'give a topic and a field path (pose.pose.position.x)';
    else if (!type) problem = `no topic ${topic} in the graph`;
    else if (this.series.has(name)) problem = `${name} is plotted already`;
    else if (this.series.size >= MAX_SERIES) problem = `at most ${MAX_SERIES} series`;
    if (problem) {
      this.say(problem, true);
      return false;
    }
    const used = new Set([...this.plot.colours.values()]);
    const colour = COLOURS.find((c) => !used.has(c)) ?? COLOURS[this.series.size % COLOURS.length];
    this.plot.colours.set(name, colour);
    const swatch = el('span', { class: 'swatch', 'aria-hidden': 'true' });
    swatch.style.background = colour; // a style property: the page's CSP allows no style attribute
    const value = el('span', { class: 'plot-value muted', text: 'waiting…' });
    const remove = el('button', { type: 'button', text: '×', 'aria-label': `remove ${name}`, title: 'remove' });
    remove.addEventListener('click', () => this.remove(name));
    const item = el('li', { dataset: { name } }, swatch, ' ', el('span', { class: 'plot-name', text: name }), ' ', value, ' ', remove);
    this.legend.append(item);
    this.series.set(name, { topic, field, item, value });
    if (!this.unsubscribe.has(topic)) {
      try {
        this.unsubscribe.set(topic, this.ros.subscribe(topic, type, (msg) => this.receive(topic, msg)));
      } catch (error) {
        this.remove(name);
        this.say(error.message, true);
        return false;
      }
    }
    this.say(`plotting ${name}`, false);
    return true;
  }

  remove(name) {
    const series = this.series.get(name);
    if (!series) return;
    this.series.delete(name);
    series.item.remove();
    this.plot.remove(name);
    const { topic } = series;
    if (![...this.series.values()].some((s) => s.topic === topic)) {
      this.unsubscribe.get(topic)?.();
      this.unsubscribe.delete(topic);
    }
  }

  receive(topic, msg) {
    if (this.paused) return;
    const t = Date.now() / 1000;
    for (const [name, series] of this.series) {
      if (series.topic !== topic) continue;
      const value = valueAt(msg, series.field);
      if (value === undefined) {
        series.value.textContent = 'no number at this path';
        continue;
      }
      this.plot.add(name, value, t);
      series.value.textContent = String(Number(value.toPrecision(6)));
    }
  }

  togglePause() {
    this.paused = !this.paused;
    const button = document.getElementById('plot-pause');
    button.textContent = this.paused ? 'Resume' : 'Pause';
    button.setAttribute('aria-pressed', String(this.paused));
  }

  // The plot's points as CSV text (csvText), in the legend's order.
  csv() {
    return csvText([...this.series.keys()].map((name) => [name, this.plot.series.get(name) ?? []]));
  }

  // A download of csv(): a Blob behind the page's link, clicked. The link keeps its
  // URL (until the next export) so that it can be followed again.
  exportCsv() {
    if (this.download.href) URL.revokeObjectURL(this.download.href);
    this.download.href = URL.createObjectURL(new Blob([this.csv()], { type: 'text/csv' }));
    this.download.click();
  }

  say(text, isError) {
    this.result.className = isError ? 'error' : 'muted';
    this.result.textContent = text;
  }
}
