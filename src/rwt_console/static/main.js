// The console's entry point: finds the server (/console/config.json), connects,
// authenticates when the server asks for it, and wires the views together.
import { ActionView, ServiceView } from './calls.js';
import { GraphView } from './graph.js';
import { ImagesView } from './images.js';
import { Rosbridge } from './rosbridge.js';
import { TfView } from './tf.js';
import { TopicView } from './topic.js';
import { el } from './ui.js';

const REFRESH_MS = 2000;
const MAX_LOG = 200;

function websocketUrl(config) {
  const ws = config.websocket;
  const scheme = ws.tls ? 'wss' : 'ws';
  const host = ws.port ? `${location.hostname}:${ws.port}` : location.host;
  return `${scheme}://${host}${ws.path}`;
}

function setStatus(text, state) {
  const status = document.getElementById('status');
  status.textContent = text;
  status.className = `status ${state}`;
}

function askForAuth() {
  const form = document.getElementById('auth');
  form.hidden = false;
  const json = document.getElementById('auth-json');
  json.addEventListener('input', () => {
    try {
      const op = JSON.parse(json.value);
      for (const [name, value] of Object.entries(op)) {
        if (form.elements[name]) form.elements[name].value = value;
      }
    } catch {
      // not JSON (yet): the fields stay as typed
    }
  });
  return new Promise((resolve) => {
    form.addEventListener('submit', (event) => {
      event.preventDefault();
      const fields = {};
      for (const name of ['mac', 'client', 'dest', 'rand', 'level']) fields[name] = form.elements[name].value;
      for (const name of ['t', 'end']) fields[name] = Number(form.elements[name].value);
      resolve(fields);
    }, { once: true });
  });
}

function wireTabs(onChange) {
  const buttons = document.querySelectorAll('#tabs button');
  const select = (name) => {
    for (const button of buttons) button.classList.toggle('active', button.dataset.tab === name);
    for (const section of document.querySelectorAll('main .tab')) section.hidden = section.id !== `tab-${name}`;
    onChange(name);
  };
  for (const button of buttons) button.addEventListener('click', () => select(button.dataset.tab));
  return select;
}

function logStatus(message) {
  if (message.level !== 'warning' && message.level !== 'error') return;
  const log = document.getElementById('server-log');
  log.prepend(el('li', { class: message.level === 'error' ? 'error' : '' },
    `${new Date().toLocaleTimeString()} ${message.level}: ${message.msg}`));
  while (log.children.length > MAX_LOG) log.lastChild.remove();
}

function watchClients(ros, types) {
  if (types.has('/client_count')) {
    ros.subscribe('/client_count', types.get('/client_count'), (msg) => {
      document.getElementById('client-count').textContent = msg.data;
    });
  }
  if (types.has('/connected_clients')) {
    ros.subscribe('/connected_clients', types.get('/connected_clients'), (msg) => {
      const body = document.querySelector('#clients tbody');
      body.replaceChildren(...(msg.clients ?? []).map((client) => {
        const since = client.connection_time ?? {};
        const seconds = (since.sec ?? since.secs ?? 0) + (since.nanosec ?? since.nsecs ?? 0) / 1e9;
        return el('tr', {}, el('td', { text: client.ip_address }),
          el('td', { text: new Date(seconds * 1000).toLocaleString() }));
      }));
    });
  }
}

async function connect(config) {
  const url = websocketUrl(config);
  document.getElementById('server-url').textContent = url;
  const ros = new Rosbridge(url);
  ros.on('status', logStatus);
  ros.on('close', (event) => {
    const why = `${event.code}${event.reason ? ` ${event.reason}` : ''}`;
    setStatus(`disconnected (${why}): reload the page to reconnect`, 'bad');
  });
  let auth = null;
  if (config.auth) {
    setStatus('authentication needed', 'bad');
    auth = await askForAuth();
  }
  await ros.connect();
  if (auth) ros.authenticate(auth);
  // the server answers nothing to a good auth op and closes on a bad one: a first call tells
  await ros.callService('/rosapi/topics');
  document.getElementById('auth').hidden = true;
  setStatus('connected', 'ok');
  return ros;
}

function showLimits(limits) {
  const body = document.querySelector('#limits tbody');
  body.replaceChildren(...Object.entries(limits ?? {}).map(([name, value]) =>
    el('tr', { dataset: { name } }, el('td', { text: name }), el('td', { text: String(value) }))));
}

async function main() {
  const response = await fetch('/console/config.json', { cache: 'no-store' });
  const config = await response.json();
  showLimits(config.limits);
  let ros;
  try {
    ros = await connect(config);
  } catch (error) {
    setStatus(config.auth ? `refused: ${error.message}` : error.message, 'bad');
    if (config.auth) document.getElementById('auth-error').textContent = 'the server refused this auth op';
    return;
  }
  const graph = new GraphView(ros, {
    topic: (name, type) => {
      selectTab('topic');
      graph.selected = name;
      for (const row of document.querySelectorAll('#topics tbody tr')) row.classList.toggle('selected', row.dataset.name === name);
      topics.show(name, type);
    },
    service: (name) => {
      selectTab('service');
      services.show(name);
    },
    action: (name) => {
      selectTab('action');
      actions.show(name);
    },
  });
  const topics = new TopicView(ros, graph);
  const services = new ServiceView(ros);
  const actions = new ActionView(ros);
  const images = new ImagesView(config);
  const tf = new TfView(ros);
  let types = new Map();
  const selectTab = wireTabs((name) => {
    images.setActive(name === 'images');
    if (name === 'tf') tf.start(types);
  });
  let clientsWatched = false;
  let refreshing = false; // a slow graph must not pile up refreshes
  const refresh = async () => {
    if (refreshing) return;
    refreshing = true;
    try {
      await graph.refresh();
      const rows = [...document.querySelectorAll('#topics tbody tr')];
      types = new Map(rows.map((row) => [row.dataset.name, row.dataset.type]));
      images.update([...types]);
      if (!clientsWatched) {
        clientsWatched = true;
        watchClients(ros, types);
      }
    } catch (error) {
      logStatus({ level: 'error', msg: `refresh failed: ${error.message}` });
    } finally {
      refreshing = false;
    }
  };
  document.getElementById('refresh').addEventListener('click', refresh);
  await refresh();
  setInterval(() => {
    if (document.getElementById('auto-refresh').checked && ros.connected) refresh();
  }, REFRESH_MS);
}

main().catch((error) => setStatus(`console failed: ${error.message}`, 'bad'));
