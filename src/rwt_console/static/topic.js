// One topic: live echo (JSON tree, pause, last N), plots of its numeric fields,
// its rate and bandwidth, and a publish form generated from its type.
import { typedefForm } from './forms.js';
import { Meter } from './meter.js';
import { Plot, numericFields } from './plot.js';
import { el, formatBytes, jsonTree, showError } from './ui.js';

const REFUSAL_WAIT_MS = 3000;
const ECHO_INTERVAL_MS = 100; // the echo redraws at most 10 times a second
// Camera-sized types: 30 frames a second of 640x480 are 37 MB/s of JSON, more than a
// page reads and parses while staying responsive (benchmarks/README.md, console), so
// the server sends these at most as often as the echo draws (throttle_rate, D12).
const THROTTLED_TYPES = new Set(['sensor_msgs/Image', 'sensor_msgs/CompressedImage',
  'sensor_msgs/PointCloud2', 'sensor_msgs/msg/Image', 'sensor_msgs/msg/CompressedImage',
  'sensor_msgs/msg/PointCloud2']);

export class TopicView {
  // onPlot(topic, field): puts a field on the Plot tab, beside other topics' fields;
  // true when it did
  constructor(ros, graph, onPlot) {
    this.ros = ros;
    this.graph = graph;
    this.onPlot = onPlot;
    this.topic = null;
    this.unsubscribe = null;
    this.paused = false;
    this.plot = new Plot(document.getElementById('plot'));
    this.plotted = new Set();
    this.form = null;
    document.getElementById('echo-pause').addEventListener('click', () => this.togglePause());
    document.getElementById('publish-form').addEventListener('submit', (event) => {
      event.preventDefault();
      this.publish();
    });
    setInterval(() => this.showStats(), 1000);
  }

  async show(topic, type) {
    if (this.unsubscribe) this.unsubscribe();
    if (this.topic) this.graph.meters.delete(this.topic);
    this.topic = topic;
    clearTimeout(this.drawTimer);
    this.drawTimer = null;
    this.pending = null;
    this.type = type;
    this.plotted.clear();
    this.plot.clear();
    document.getElementById('plot-fields').replaceChildren();
    document.getElementById('topic-hint').hidden = true;
    document.getElementById('topic-view').hidden = false;
    document.getElementById('topic-name').textContent = topic;
    document.getElementById('topic-type').textContent = type;
    document.getElementById('echo-output').replaceChildren();
    document.getElementById('publish-result').textContent = '';
    const meter = new Meter();
    this.meter = meter;
    this.graph.meters.set(topic, meter);
    const fields = document.getElementById('publish-fields');
    try {
      this.throttled = THROTTLED_TYPES.has(type);
      const options = this.throttled ? { throttle_rate: ECHO_INTERVAL_MS } : {};
      this.unsubscribe = this.ros.subscribe(topic, type, (msg, bytes, replayed) => {
        if (!replayed) meter.record(bytes); // the rate counts what arrives, not a replay
        this.receive(msg);
      }, options);
    } catch (error) {
      this.unsubscribe = null;
      showError(document.getElementById('echo-output'), error);
    }
    fields.replaceChildren(el('p', { class: 'muted', text: 'loading the type…' }));
    try {
      const details = await this.ros.callService('/rosapi/message_details', { type });
      if (this.topic !== topic) return;
      this.form = typedefForm(details.typedefs, 'msg');
      fields.replaceChildren(this.form.node);
    } catch (error) {
      showError(fields, error);
    }
  }

  receive(msg) {
    const t = performance.now() / 1000;
    const numbers = numericFields(msg);
    this.offerPlotFields(numbers);
    for (const [name, value] of numbers) if (this.plotted.has(name)) this.plot.add(name, value, t);
    if (this.paused) return;
    // a fast topic (a camera at 30 Hz) is drawn at most every ECHO_INTERVAL_MS, the
    // newest message each time: building its tree is what costs, not receiving it
    this.pending = msg;
    if (this.drawTimer) return;
    const wait = Math.max(0, (this.drawnAt ?? 0) + ECHO_INTERVAL_MS - performance.now());
    this.drawTimer = setTimeout(() => this.draw(), wait);
  }

  draw() {
    this.drawTimer = null;
    const msg = this.pending;
    this.pending = null;
    if (msg === null || this.paused) return;
    this.drawnAt = performance.now();
    const output = document.getElementById('echo-output');
    output.prepend(el('div', { class: 'message' }, jsonTree(msg)));
    const keep = Math.max(1, Math.min(100, Number(document.getElementById('echo-keep').value) || 5));
    while (output.children.length > keep) output.lastChild.remove();
  }

  offerPlotFields(numbers) {
    const box = document.getElementById('plot-fields');
    if (box.children.length || numbers.length === 0) return;
    for (const [name] of numbers.slice(0, 24)) {
      const input = el('input', { type: 'checkbox', value: name });
      input.addEventListener('change', () => {
        if (input.checked) this.plotted.add(name);
        else this.plotted.delete(name);
      });
      const topic = this.topic;
      const add = el('button', { type: 'button', class: 'plot-add', text: '+', title: 'add to the Plot tab',
        'aria-label': `plot ${topic} ${name} on the Plot tab` });
      add.addEventListener('click', () => {
        if (this.onPlot(topic, name)) add.textContent = '✓';
      });
      box.append(el('span', { class: 'plot-field' }, el('label', {}, input, ` ${name}`), add));
    }
    if (numbers.length > 0 && numbers.length <= 3) {
      for (const input of box.querySelectorAll('input')) {
        input.checked = true;
        this.plotted.add(input.value);
      }
    }
  }

  togglePause() {
    this.paused = !this.paused;
    document.getElementById('echo-pause').textContent = this.paused ? 'Resume' : 'Pause';
  }

  showStats() {
    if (!this.meter) return;
    const reading = this.meter.read();
    const { hz, bytesPerSecond } = reading;
    document.getElementById('echo-stats').textContent = `${hz.toFixed(1)} Hz, ${formatBytes(bytesPerSecond)}`
      + (this.throttled ? ' (sent at most 10 a second)' : '');
    // as ros2 topic hz and ros2 topic bw print them
    document.getElementById('echo-details').textContent =
      `average rate ${hz.toFixed(3)}; min ${reading.minGap.toFixed(3)}s max ${reading.maxGap.toFixed(3)}s`
      + ` std dev ${reading.stdDev.toFixed(5)}s window ${reading.window};`
      + ` ${formatBytes(bytesPerSecond)} from ${reading.window} messages,`
      + ` mean ${reading.meanSize.toFixed(0)} B min ${reading.minSize} B max ${reading.maxSize} B`;
    this.graph.showRates();
  }

  // The server answers a good publish with nothing and a refused one with an error
  // status naming its id: shown here, beside the button, for REFUSAL_WAIT_MS.
  async publish() {
    const result = document.getElementById('publish-result');
    let ids;
    try {
      const msg = this.form.read();
      ids = this.ros.publish(this.topic, this.type, msg);
      result.className = 'muted';
      result.textContent = `published at ${new Date().toLocaleTimeString()}`;
    } catch (error) {
      result.className = 'error';
      result.textContent = error.message;
      return;
    }
    const refused = await this.ros.errorFor(ids, REFUSAL_WAIT_MS);
    if (refused) {
      result.className = 'error';
      result.textContent = `refused: ${refused.msg}`;
    }
  }
}
