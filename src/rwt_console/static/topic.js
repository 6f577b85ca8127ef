// One topic: live echo (JSON tree, pause, last N), plots of its numeric fields,
// its rate and bandwidth, and a publish form generated from its type.
import { typedefForm } from './forms.js';
import { Meter } from './meter.js';
import { Plot, numericFields } from './plot.js';
import { el, formatBytes, jsonTree, showError } from './ui.js';

export class TopicView {
  constructor(ros, graph) {
    this.ros = ros;
    this.graph = graph;
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
      this.unsubscribe = this.ros.subscribe(topic, type, (msg, bytes, replayed) => {
        if (!replayed) meter.record(bytes); // the rate counts what arrives, not a replay
        this.receive(msg);
      });
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
      box.append(el('label', {}, input, ` ${name}`));
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
    const { hz, bytesPerSecond } = this.meter.read();
    document.getElementById('echo-stats').textContent = `${hz.toFixed(1)} Hz, ${formatBytes(bytesPerSecond)}`;
    this.graph.showRates();
  }

  publish() {
    const result = document.getElementById('publish-result');
    try {
      const msg = this.form.read();
      this.ros.publish(this.topic, this.type, msg);
      result.className = 'muted';
      result.textContent = `published at ${new Date().toLocaleTimeString()}`;
    } catch (error) {
      result.className = 'error';
      result.textContent = error.message;
    }
  }
}
