// The node graph, as rqt_graph draws it: nodes (ellipses) and topics (boxes), an edge
// node -> topic for each publication and topic -> node for each subscription, from
// /rosapi/nodes and /rosapi/node_details, laid out in layers (longest path, cycles
// broken) and drawn in SVG by this page. Updated in place: an item keeps its element,
// and its place while the graph does not change.
import { choosable } from './ui.js';

let svgNamespace = null; // set from the page's <svg>
const MAX_NODES = 200; // node_details costs one call per node at each refresh
const CHAR_PX = 7.3; // the width of a character of the 12 px monospace labels
const ROW_PX = 34;
const LAYER_GAP_PX = 70;
const PAD_PX = 12;
// rwt's own nodes, and the topics rqt_graph's "hide debug" hides (its quiet names, ROS 2's)
const OWN_NODES = new Set(['/rosapi', '/rosbridge_websocket', '/tf2_web_republisher']);
const DEBUG_TOPICS = new Set(['/rosout', '/rosout_agg', '/parameter_events', '/clock', '/statistics',
  '/diagnostics', '/diagnostics_agg', '/diag_agg', '/client_count', '/connected_clients']);

export class NodeGraphView {
  // onTopic(name): a topic was chosen (its echo opens).
  constructor(ros, onTopic) {
    this.ros = ros;
    this.onTopic = onTopic;
    this.active = false;
    this.busy = false;
    this.details = null; // [[node, {publishing, subscribing, services}], ...], last read
    this.rounds = 0;
    this.svg = document.getElementById('node-graph');
    svgNamespace = this.svg.namespaceURI; // the <svg> of the page is in SVG's namespace
    this.edgeLayer = svgEl('g', { class: 'ng-edges' });
    this.itemLayer = svgEl('g', { class: 'ng-items' });
    const marker = svgEl('marker', { id: 'ng-arrow', viewBox: '0 0 10 10', refX: '10', refY: '5',
      markerWidth: '7', markerHeight: '7', orient: 'auto-start-reverse' });
    marker.append(svgEl('path', { d: 'M0,0 L10,5 L0,10 z' }));
    const defs = svgEl('defs');
    defs.append(marker);
    this.svg.append(defs, this.edgeLayer, this.itemLayer);
    this.items = new Map(); // vertex id -> its <g>
    this.paths = new Map(); // 'from>to' -> its <path>
    this.hideDebug = document.getElementById('node-graph-hide-debug');
    this.hideDebug.addEventListener('change', () => this.draw());
    this.error = document.getElementById('node-graph-error');
    this.summary = document.getElementById('node-graph-summary');
  }

  setActive(active) {
    this.active = active;
    if (active) this.refresh();
  }

  async refresh() {
    if (!this.active || this.busy) return;
    this.busy = true;
    try {
      const { nodes } = await this.ros.callService('/rosapi/nodes');
      const read = await Promise.all(nodes.slice(0, MAX_NODES).map((node) =>
        // a node may go between the two calls: it is left out, not an error
        this.ros.callService('/rosapi/node_details', { node }).then((d) => [node, d], () => null)));
      this.details = read.filter(Boolean);
      this.error.textContent = nodes.length > MAX_NODES ? `the first ${MAX_NODES} of ${nodes.length} nodes` : '';
      this.draw();
    } catch (error) {
      this.error.textContent = `cannot read the graph: ${error.message}`;
    } finally {
      this.busy = false;
    }
  }

  // This page's own connection: a client node that subscribes only to topics the page
  // subscribes to (not necessarily all of them: the page may have subscribed since the
  // server answered node_details) and publishes only what the page advertised.
  isThisPage(node, details) {
    if (!node.startsWith('/rwt_client_') || details.services.length) return false;
    if (!details.subscribing.length) return false;
    const mine = this.ros.subscribed;
    return details.subscribing.every((t) => mine.has(t))
      && details.publishing.every((t) => this.ros.advertised.has(t));
  }

  // The vertices ('n:' node, 't:' topic) and edges [from, to] shown.
  model() {
    const hide = this.hideDebug.checked;
    const vertices = new Map(); // id -> {kind, name, services}
    const edges = [];
    for (const [node, d] of this.details ?? []) {
      const details = { publishing: d.publishing ?? [], subscribing: d.subscribing ?? [], services: d.services ?? [] };
      if (hide && (OWN_NODES.has(node) || this.isThisPage(node, details))) continue;
      vertices.set(`n:${node}`, { kind: 'node', name: node, services: details.services });
      const shown = (topic) => !(hide && DEBUG_TOPICS.has(topic));
      for (const topic of details.publishing.filter(shown)) {
        vertices.set(`t:${topic}`, { kind: 'topic', name: topic });
        edges.push([`n:${node}`, `t:${topic}`]);
      }
      for (const topic of details.subscribing.filter(shown)) {
        vertices.set(`t:${topic}`, { kind: 'topic', name: topic });
        edges.push([`t:${topic}`, `n:${node}`]);
      }
    }
    return { vertices, edges };
  }

  draw() {
    if (!this.details) return;
    const { vertices, edges } = this.model();
    const places = layout(vertices, edges);
    const seen = new Set();
    for (const [id, vertex] of vertices) {
      seen.add(id);
      const place = places.get(id);
      let item = this.items.get(id);
      if (!item) {
        item = this.makeItem(id, vertex);
        this.items.set(id, item);
        this.itemLayer.append(item);
      }
      setAttr(item, 'transform', `translate(${place.x},${place.y})`);
      if (vertex.kind === 'node') {
        const services = vertex.services.length ? `; services: ${vertex.services.join(', ')}` : '';
        setText(item.querySelector('title'), `node ${vertex.name}${services}`);
      }
    }
    for (const [id, item] of this.items) {
      if (!seen.has(id)) {
        item.remove();
        this.items.delete(id);
      }
    }
    const keys = new Set();
    for (const [from, to] of edges) {
      const key = `${from}>${to}`;
      keys.add(key);
      let path = this.paths.get(key);
      if (!path) {
        path = svgEl('path', { class: 'ng-edge', 'marker-end': 'url(#ng-arrow)' });
        Object.assign(path.dataset, { key, from: vertices.get(from).name, to: vertices.get(to).name });
        this.paths.set(key, path);
        this.edgeLayer.append(path);
      }
      setAttr(path, 'd', edgePath(places.get(from), places.get(to)));
    }
    for (const [key, path] of this.paths) {
      if (!keys.has(key)) {
        path.remove();
        this.paths.delete(key);
      }
    }
    let width = 0;
    let height = 0;
    for (const place of places.values()) {
      width = Math.max(width, place.x + place.width + PAD_PX);
      height = Math.max(height, place.y + ROW_PX + PAD_PX);
    }
    setAttr(this.svg, 'width', String(Math.ceil(width)));
    setAttr(this.svg, 'height', String(Math.ceil(height)));
    const counts = [...vertices.values()].reduce((n, v) => ((n[v.kind] += 1), n), { node: 0, topic: 0 });
    setText(this.summary, `${counts.node} nodes, ${counts.topic} topics, ${edges.length} connections`);
    this.rounds += 1;
    this.svg.dataset.rounds = String(this.rounds);
  }

  makeItem(id, vertex) {
    const width = labelWidth(vertex.name);
    const item = svgEl('g', { class: `ng-${vertex.kind}` });
    Object.assign(item.dataset, { id, name: vertex.name, kind: vertex.kind });
    const shape = vertex.kind === 'node'
      ? svgEl('ellipse', { cx: width / 2, cy: ROW_PX / 2 - 4, rx: width / 2, ry: ROW_PX / 2 - 5 })
      : svgEl('rect', { x: 0, y: 4, width, height: ROW_PX - 16, rx: 3 });
    const label = svgEl('text', { x: width / 2, y: ROW_PX / 2, 'text-anchor': 'middle' });
    label.textContent = vertex.name; // a name is text, never markup
    const title = svgEl('title');
    title.textContent = `${vertex.kind} ${vertex.name}`;
    item.append(title, shape, label);
    if (vertex.kind === 'topic') {
      choosable(item, () => this.onTopic(vertex.name));
      item.setAttribute('aria-label', `topic ${vertex.name}: open its echo`);
    }
    return item;
  }
}

function svgEl(tag, attributes = {}) {
  const node = document.createElementNS(svgNamespace, tag);
  for (const [name, value] of Object.entries(attributes)) node.setAttribute(name, String(value));
  return node;
}

// Only what changed is written: an unchanged graph does not touch the DOM.
function setAttr(node, name, value) {
  if (node.getAttribute(name) !== value) node.setAttribute(name, value);
}

function setText(node, text) {
  if (node.textContent !== text) node.textContent = text;
}

function labelWidth(name) {
  return Math.ceil(name.length * CHAR_PX + 24);
}

// A curve from the right of `from` to the left of `to` (around, for an edge going back).
function edgePath(from, to) {
  const x1 = from.x + from.width;
  const y1 = from.y + ROW_PX / 2 - 4;
  const x2 = to.x;
  const y2 = to.y + ROW_PX / 2 - 4;
  const bend = Math.max(40, Math.abs(x2 - x1) / 2);
  return `M${x1},${y1} C${x1 + bend},${y1} ${x2 - bend},${y2} ${x2},${y2}`;
}

// Layers by longest path from the sources (edges closing a cycle are left out of the
// ranking), ordered within a layer by the mean place of their neighbours (two sweeps),
// from names sorted first: the same graph always gets the same picture.
export function layout(vertices, edges) {
  const ids = [...vertices.keys()].sort();
  const out = new Map(ids.map((id) => [id, []]));
  const into = new Map(ids.map((id) => [id, []]));
  for (const [from, to] of edges) {
    out.get(from).push(to);
    into.get(to).push(from);
  }
  // depth-first from the sources, then from what is left: an edge to a vertex on the
  // stack closes a cycle and does not rank
  const state = new Map(); // id -> 1 on the stack, 2 done
  const ranked = new Map(ids.map((id) => [id, []])); // id -> predecessors that rank it
  const visit = (id) => {
    state.set(id, 1);
    for (const next of [...new Set(out.get(id))].sort()) {
      if (state.get(next) === 1) continue;
      ranked.get(next).push(id);
      if (!state.has(next)) visit(next);
    }
    state.set(id, 2);
  };
  for (const id of ids) if (!into.get(id).length && !state.has(id)) visit(id);
  for (const id of ids) if (!state.has(id)) visit(id);
  const layerOf = new Map();
  const rank = (id) => {
    if (!layerOf.has(id)) {
      layerOf.set(id, 0); // a placeholder: ranked edges have no cycle
      layerOf.set(id, Math.max(0, ...ranked.get(id).map((p) => rank(p) + 1)));
    }
    return layerOf.get(id);
  };
  const layers = [];
  for (const id of ids) {
    const layer = rank(id);
    while (layers.length <= layer) layers.push([]);
    layers[layer].push(id);
  }
  const order = new Map();
  const number = () => layers.forEach((layer) => layer.forEach((id, i) => order.set(id, i)));
  number();
  const sweep = (range, neighbours) => {
    for (const l of range) {
      const mean = new Map(layers[l].map((id) => {
        const placed = neighbours.get(id).filter((n) => layerOf.get(n) !== l).map((n) => order.get(n));
        return [id, placed.length ? placed.reduce((a, b) => a + b, 0) / placed.length : order.get(id)];
      }));
      layers[l].sort((a, b) => mean.get(a) - mean.get(b) || order.get(a) - order.get(b));
      layers[l].forEach((id, i) => order.set(id, i));
    }
  };
  const up = [...layers.keys()];
  for (let i = 0; i < 2; i += 1) {
    sweep(up.slice(1), into);
    sweep(up.slice(0, -1).reverse(), out);
  }
  // each item level with the mean of its neighbours placed in the columns before it,
  // and below the item above it: a subscriber sits beside its topic
  const places = new Map();
  let x = PAD_PX;
  for (const layer of layers) {
    const width = Math.max(0, ...layer.map((id) => labelWidth(vertices.get(id).name)));
    let next = PAD_PX;
    for (const id of layer) {
      const placed = into.get(id).filter((n) => places.has(n)).map((n) => places.get(n).y);
      const y = Math.max(next, placed.length ? placed.reduce((a, b) => a + b, 0) / placed.length : next);
      const own = labelWidth(vertices.get(id).name);
      places.set(id, { x: x + (width - own) / 2, y, width: own });
      next = y + ROW_PX;
    }
    x += width + LAYER_GAP_PX;
  }
  return places;
}
