// The graph on the left: topics (with publisher/subscriber counts and the rates
// measured in this page), services, action servers, nodes and parameters.
import { choosable, el, formatBytes, nameMatcher, rosName, syncChildren } from './ui.js';

const MAX_COUNTED_TOPICS = 200; // publisher/subscriber counts cost two calls per topic
const MAX_PARAM_VALUES = 100;
// counts are asked for every COUNT_EVERY refreshes (20 s), the selected topic's each
// time: 200 topics cost 400 calls a round, which every 2 s was 200 calls a second
const COUNT_EVERY = 10;

export class GraphView {
  constructor(ros, handlers) {
    this.ros = ros;
    this.handlers = handlers; // {topic(name, type), service(name), action(name)}
    this.meters = new Map(); // topic -> Meter (set by the topic view)
    this.selected = null;
    this.counts = new Map(); // topic -> [publishers, subscribers], last asked
    this.rounds = 0;
    this.filter = document.getElementById('graph-filter');
    this.filter.addEventListener('input', () => this.applyFilter());
  }

  // Hide the rows and items whose name does not match the filter (nameMatcher).
  applyFilter() {
    const matches = nameMatcher(this.filter.value);
    for (const node of document.querySelectorAll('#graph [data-name]')) node.hidden = !matches(node.dataset.name);
  }

  async refresh() {
    const ros = this.ros;
    const [topics, services, actions, nodes, params] = await Promise.all([
      ros.callService('/rosapi/topics'),
      ros.callService('/rosapi/services'),
      ros.callService('/rosapi/action_servers').catch(() => ({ action_servers: [] })),
      ros.callService('/rosapi/nodes'),
      ros.callService('/rosapi/get_param_names').catch(() => ({ names: [] })),
    ]);
    await this.showTopics(topics.topics, topics.types);
    this.showList('services', services.services, (name) => this.handlers.service(name));
    this.showList('actions', actions.action_servers, (name) => this.handlers.action(name));
    this.showList('nodes', nodes.nodes, null);
    await this.showParams(params.names);
    this.applyFilter();
  }

  async showTopics(names, types) {
    const full = this.rounds % COUNT_EVERY === 0;
    this.rounds += 1;
    const counted = names.slice(0, MAX_COUNTED_TOPICS)
      .filter((topic) => full || topic === this.selected || !this.counts.has(topic));
    await Promise.all(counted.map(async (topic) => {
      const [pubs, subs] = await Promise.all([
        this.ros.callService('/rosapi/publishers', { topic }),
        this.ros.callService('/rosapi/subscribers', { topic }),
      ]);
      this.counts.set(topic, [pubs.publishers.length, subs.subscribers.length]);
    }));
    const known = new Set(names);
    for (const topic of this.counts.keys()) if (!known.has(topic)) this.counts.delete(topic);
    const counts = names.map((topic) => this.counts.get(topic));
    const body = document.querySelector('#topics tbody');
    const index = new Map(names.map((name, i) => [name, i]));
    const setText = (cell, text) => {
      if (cell.textContent !== String(text)) cell.textContent = text;
    };
    syncChildren(body, names, (name) => {
      const row = el('tr', { dataset: { name } },
        el('td', {}, rosName(name)), el('td', { class: 'muted' }), el('td'), el('td'),
        el('td', { class: 'hz' }), el('td', { class: 'bw' }));
      // the type is read when chosen: it may change while the row stays
      return choosable(row, () => this.handlers.topic(name, row.dataset.type));
    }, () => {});
    for (const row of body.children) {
      const i = index.get(row.dataset.name);
      const [pubs, subs] = counts[i] ?? ['?', '?'];
      if (row.dataset.type !== types[i]) row.dataset.type = types[i]; // a write is a mutation
      // a type wraps after a '/' as a name does: a long one must not widen the table
      if (row.cells[1].textContent !== types[i]) row.cells[1].replaceChildren(rosName(types[i]));
      setText(row.cells[2], pubs);
      setText(row.cells[3], subs);
      row.classList.toggle('selected', row.dataset.name === this.selected);
    }
    document.getElementById('topic-count').textContent = `(${names.length})`;
    this.showRates();
  }

  showRates() {
    for (const row of document.querySelectorAll('#topics tbody tr')) {
      const meter = this.meters.get(row.dataset.name);
      const reading = meter ? meter.read() : null;
      row.querySelector('.hz').textContent = reading ? reading.hz.toFixed(1) : '';
      row.querySelector('.bw').textContent = reading ? formatBytes(reading.bytesPerSecond) : '';
    }
  }

  showList(id, names, onChoose) {
    const list = document.getElementById(id);
    syncChildren(list, names, (name) => {
      const item = el('li', { dataset: { name } }, rosName(name));
      return onChoose ? choosable(item, () => onChoose(name)) : item;
    }, () => {});
    document.getElementById(`${id.replace(/s$/, '')}-count`).textContent = `(${names.length})`;
  }

  async showParams(names) {
    const values = await Promise.all(names.slice(0, MAX_PARAM_VALUES).map((name) =>
      this.ros.callService('/rosapi/get_param', { name }).then((r) => r.value, () => '?')));
    const body = document.querySelector('#params tbody');
    const shown = new Map(names.map((name, i) => [name, values[i] ?? '']));
    syncChildren(body, names,
      (name) => el('tr', { dataset: { name } }, el('td', {}, rosName(name)), el('td', { class: 'muted' })),
      () => {});
    for (const row of body.children) {
      const text = String(shown.get(row.dataset.name));
      if (row.cells[1].textContent !== text) row.cells[1].textContent = text;
    }
    document.getElementById('param-count').textContent = `(${names.length})`;
  }
}
