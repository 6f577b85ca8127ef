// The TF tree: frames from /tf and /tf_static, parent -> child.
import { el } from './ui.js';

export class TfView {
  constructor(ros) {
    this.ros = ros;
    this.parents = new Map(); // child -> parent
    this.static = new Set();
    this.pending = false;
    this.subscribed = false;
  }

  start(types) {
    if (this.subscribed) return;
    this.subscribed = true;
    const type = types.get('/tf') ?? 'tf2_msgs/msg/TFMessage';
    this.ros.subscribe('/tf', type, (msg) => this.add(msg, false), { throttle_rate: 100 });
    this.ros.subscribe('/tf_static', types.get('/tf_static') ?? type, (msg) => this.add(msg, true));
  }

  add(msg, isStatic) {
    for (const transform of msg.transforms ?? []) {
      const child = strip(transform.child_frame_id);
      this.parents.set(child, strip(transform.header.frame_id));
      if (isStatic) this.static.add(child);
    }
    if (!this.pending) {
      this.pending = true;
      setTimeout(() => this.draw(), 250);
    }
  }

  draw() {
    this.pending = false;
    const children = new Map();
    const frames = new Set([...this.parents.keys(), ...this.parents.values()]);
    for (const [child, parent] of this.parents) {
      if (!children.has(parent)) children.set(parent, []);
      children.get(parent).push(child);
    }
    const roots = [...frames].filter((frame) => !this.parents.has(frame)).sort();
    const seen = new Set();
    const branch = (frame) => {
      seen.add(frame);
      const kids = (children.get(frame) ?? []).filter((kid) => !seen.has(kid)).sort();
      const label = this.static.has(frame) ? `${frame} (static)` : frame;
      return el('li', { dataset: { frame } }, el('span', { text: label }),
        kids.length ? el('ul', {}, kids.map(branch)) : null);
    };
    const tree = el('ul', { class: 'tf-tree' }, roots.map(branch));
    const lost = [...frames].filter((frame) => !seen.has(frame)); // cycles have no root
    const out = document.getElementById('tf-tree');
    out.replaceChildren(tree);
    if (lost.length) out.append(el('p', { class: 'error', text: `in a cycle: ${lost.join(', ')}` }));
  }
}

function strip(frame) {
  return String(frame ?? '').replace(/^\//, '');
}
