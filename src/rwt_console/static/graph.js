// The graph on the left: topics (with publisher/subscriber counts and the rates
// measured in this page), services, action servers, nodes and parameters.
import { el, formatBytes } from './ui.js';

const MAX_COUNTED_TOPICS = 200; // publisher/subscriber counts cost two calls per topic
const MAX_PARAM_VALUES = 100;

export class GraphView {
  constructor(ros, handlers) {
    this.ros = ros;
    this.handlers = handlers; // {topic(name, type), service(name), action(name)}
    this.meters = new Map(); // topic -> Meter (set by the topic view)
    this.selected = null;
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
  }

  async showTopics(names, types) {
    const counts = await Promise.all(names.slice(0, MAX_COUNTED_TOPICS).map(async (topic) => {
      const [pubs, subs] = await Promise.all([
        this.ros.callService('/rosapi/publishers', { topic }),
        this.ros.callService('/rosapi/subscribers', { topic }),
      ]);
      return [pubs.publishers.length, subs.subscribers.length];
    }));
    const body = document.querySelector('#topics tbody');
    body.replaceChildren(...names.map((name, i) => {
      const [pubs, subs] = counts[i] ?? ['?', '?'];
      const row = el('tr', { dataset: { name, type: types[i] }, onclick: () => this.handlers.topic(name, types[i]) },
        el('td', { text: name }), el('td', { class: 'muted', text: types[i] }),
        el('td', { text: pubs }), el('td', { text: subs }),
        el('td', { class: 'hz' }), el('td', { class: 'bw' }));
      if (name === this.selected) row.classList.add('selected');
      return row;
    }));
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
    list.replaceChildren(...names.map((name) => el('li', {
      dataset: { name }, text: name, onclick: onChoose ? () => onChoose(name) : undefined,
    })));
    document.getElementById(`${id.replace(/s$/, '')}-count`).textContent = `(${names.length})`;
  }

  async showParams(names) {
    const values = await Promise.all(names.slice(0, MAX_PARAM_VALUES).map((name) =>
      this.ros.callService('/rosapi/get_param', { name }).then((r) => r.value, () => '?')));
    const body = document.querySelector('#params tbody');
    body.replaceChildren(...names.map((name, i) =>
      el('tr', { dataset: { name } }, el('td', { text: name }), el('td', { class: 'muted', text: values[i] ?? '' }))));
    document.getElementById('param-count').textContent = `(${names.length})`;
  }
}
