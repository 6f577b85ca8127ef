// The TF tree: frames from /tf and /tf_static (the shared TfBuffer), parent -> child.
import { el } from './ui.js';

export class TfView {
  constructor(buffer) {
    this.buffer = buffer;
    this.pending = false;
    buffer.onChange(() => {
      if (this.pending) return;
      this.pending = true;
      setTimeout(() => this.draw(), 250);
    });
  }

  start(types) {
    this.buffer.start(types);
  }

  draw() {
    this.pending = false;
    const parents = new Map([...this.buffer.frames].map(([child, t]) => [child, t.parent]));
    const children = new Map();
    const frames = this.buffer.names();
    for (const [child, parent] of parents) {
      if (!children.has(parent)) children.set(parent, []);
      children.get(parent).push(child);
    }
    const roots = [...frames].filter((frame) => !parents.has(frame)).sort();
    const seen = new Set();
    const branch = (frame) => {
      seen.add(frame);
      const kids = (children.get(frame) ?? []).filter((kid) => !seen.has(kid)).sort();
      const label = this.buffer.frames.get(frame)?.isStatic ? `${frame} (static)` : frame;
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
