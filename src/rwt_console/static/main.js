// The console's entry point: finds the server (/console/config.json), connects,
// authenticates when the server asks for it, and wires the views together.
import { ActionView, ServiceView } from './calls.js';
import { GraphView } from './graph.js';
import { ImagesView } from './images.js';
import { LogView } from './log.js';
import { ParamsView } from './params.js';
import { PlotPanel } from './plotpanel.js';
import { MapView } from './map.js';
import { NodeGraphView } from './nodegraph.js';
import { TeleopView } from './teleop.js';
import { Rosbridge } from './rosbridge.js';
import { watchSafety } from './safety.js';
import { TfView } from './tf.js';
import { TfBuffer } from './tfbuffer.js';
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

// The auth form: its fields fill from a pasted op; it never submits itself (a GET
// would put mac and rand in the URL and the history), each submit resolves waitAuth.
let authWaiter = null;

function setUpAuthForm() {
  const form = document.getElementById('auth');
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
  form.addEventListener('submit', (event) => {
    event.preventDefault();
    const fields = {};
    for (const name of ['mac', 'client', 'dest', 'rand', 'level']) fields[name] = form.elements[name].value;
    for (const name of ['t', 'end']) fields[name] = Number(form.elements[name].value);
    if (authWaiter) authWaiter(fields);
    authWaiter = null;
  });
}

function askForAuth() {
  document.getElementById('auth').hidden = false;
  return new Promise((resolve) => {
    authWaiter = resolve;
  });
}

// The tabs as ARIA describes them (tablist, tab with aria-selected, tabpanel), so a
// screen reader names them and a keyboard moves between them with the arrow keys.
function wireTabs(onChange) {
  const buttons = [...document.querySelectorAll('#tabs button')];
  document.getElementById('tabs').setAttribute('role', 'tablist');
  for (const button of buttons) {
    button.setAttribute('role', 'tab');
    button.setAttribute('aria-controls', `tab-${button.dataset.tab}`);
  }
  for (const section of document.querySelectorAll('main .tab')) section.setAttribute('role', 'tabpanel');
  const select = (name) => {
    for (const button of buttons) {
      const active = button.dataset.tab === name;
      button.classList.toggle('active', active);
      button.setAttribute('aria-selected', String(active));
      button.tabIndex = active ? 0 : -1;
    }
    for (const section of document.querySelectorAll('main .tab')) section.hidden = section.id !== `tab-${name}`;
    onChange(name);
  };
  buttons.forEach((button, i) => {
    button.addEventListener('click', () => select(button.dataset.tab));
    button.addEventListener('keydown', (event) => {
      const step = { ArrowRight: 1, ArrowLeft: -1 }[event.key];
      if (!step) return;
      const next = buttons[(i + step + buttons.length) % buttons.length];
      next.focus();
      select(next.dataset.tab);
    });
  });
  const active = buttons.find((button) => button.classList.contains('active')) ?? buttons[0];
  select(active.dataset.tab);
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

// ?webrtc in the page's URL: the rosbridge data channel of `rwt serve --webrtc`
// (docs/console.md), its offer posted to this origin's /webrtc, instead of the WebSocket
const webrtc = new URLSearchParams(location.search).has('webrtc') ? location.origin : null;

async function connectOnce(url, auth) {
  const ros = new Rosbridge(url, { webrtc });
  let closed = null;
  ros.on('close', (event) => {
    closed = event;
  });
  await ros.connect();
  if (auth) ros.authenticate(auth);
  // the server answers nothing to a good auth op and closes on a bad one: a first call tells
  try {
    await ros.callService('/rosapi/topics');
  } catch (error) {
    // the close names the reason (a bad MAC, an expired op...): say it, not the call's fate
    await new Promise((resolve) => setTimeout(resolve, 50));
    if (closed && closed.reason) throw new Error(closed.reason);
    throw error;
  }
  return ros;
}

async function connect(config) {
  const url = websocketUrl(config);
  document.getElementById('server-url').textContent = webrtc ? `${webrtc}/webrtc (WebRTC)` : url;
  if (config.foxglove) {
    document.getElementById('foxglove-url').textContent = url;
    document.getElementById('foxglove-token').hidden = !config.auth;
    document.getElementById('foxglove-help').hidden = false;
  }
  let ros;
  if (!config.auth) {
    ros = await connectOnce(url, null);
  } else {
    setUpAuthForm();
    setStatus('authentication needed', 'bad');
    for (;;) {
      const auth = await askForAuth();
      try {
        ros = await connectOnce(url, auth);
        break;
      } catch (error) {
        setStatus(`refused: ${error.message}`, 'bad');
        document.getElementById('auth-error').textContent = `the server refused this auth op: ${error.message}`;
      }
    }
  }
  ros.on('status', logStatus);
  let lastClose = '';
  ros.on('close', (event) => {
    lastClose = `${event.code}${event.reason ? ` ${event.reason}` : ''}`;
    setStatus(`disconnected (${lastClose})`, 'bad');
  });
  ros.on('reconnecting', (delay) => {
    setStatus(`disconnected (${lastClose}): reconnecting in ${(delay / 1000).toFixed(1)} s`, 'bad');
  });
  ros.on('open', () => {
    setStatus('connected', 'ok');
    ros.setLevel('warning');
  });
  ros.reconnect();
  // connections start at level error (docs/limits.md): the Server tab shows warnings too,
  // such as messages dropped for this page reading slowly
  ros.setLevel('warning');
  document.getElementById('auth').hidden = true;
  document.getElementById('auth-error').textContent = '';
  setStatus('connected', 'ok');
  return ros;
}

function showLimits(limits) {
  const body = document.querySelector('#limits tbody');
  body.replaceChildren(...Object.entries(limits ?? {}).map(([name, value]) =>
    el('tr', { dataset: { name } }, el('td', { text: name }), el('td', { text: String(value) }))));
}

// The versions from GET /version (docs/server.md, "Version endpoint"), when the page
// is served from the WebSocket port itself; elsewhere (the video port) it is not asked.
async function showVersion(config) {
  if (config.websocket.port) return;
  try {
    const response = await fetch('/version', { cache: 'no-store' });
    if (!response.ok) return;
    const { protocol, server } = await response.json();
    document.getElementById('server-version').textContent =
      `rwt ${server} · protocol ${protocol.major}.${protocol.minor}.${protocol.patch}`;
  } catch {
    // an older server without /version: the header shows no version
  }
}

async function main() {
  const response = await fetch('/console/config.json', { cache: 'no-store' });
  const config = await response.json();
  showLimits(config.limits);
  showVersion(config); // not awaited: the connection does not wait for it
  let ros;
  try {
    ros = await connect(config);
  } catch (error) {
    setStatus(error.message, 'bad');
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
  const plots = new PlotPanel(ros, (topic) => types.get(topic));
  const params = new ParamsView(ros);
  const topics = new TopicView(ros, graph, (topic, field) => plots.add(topic, field));
  const services = new ServiceView(ros);
  const actions = new ActionView(ros);
  const images = new ImagesView(config, ros);
  const tfBuffer = new TfBuffer(ros);
  const tf = new TfView(tfBuffer);
  const map = new MapView(ros, tfBuffer);
  const nodeGraph = new NodeGraphView(ros, (name) => graph.handlers.topic(name, types.get(name)));
  const log = new LogView(ros);
  new TeleopView(ros, (topic) => types.get(topic)); // eslint-disable-line no-new
  let types = new Map();
  const selectTab = wireTabs((name) => {
    images.setActive(name === 'images');
    if (name === 'tf') tf.start(types);
    if (name === 'log') log.start(types);
    if (name === 'params') params.refresh();
    if (name === 'plot') plots.showTopics(types.keys());
    nodeGraph.setActive(name === 'node-graph');
    map.setActive(name === 'map', types);
  });
  let clientsWatched = false;
  let refreshing = false; // a slow graph must not pile up refreshes
  const refresh = async () => {
    if (refreshing) return;
    refreshing = true;
    try {
      await graph.refresh();
      nodeGraph.refresh(); // its own calls, not awaited: one node per call
      const rows = [...document.querySelectorAll('#topics tbody tr')];
      types = new Map(rows.map((row) => [row.dataset.name, row.dataset.type]));
      images.update([...types]);
      if (!clientsWatched) {
        clientsWatched = true;
        watchClients(ros, types);
        watchSafety(ros, types);
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
