// DOM helpers shared by the console's views: element building and the JSON tree.

export function el(tag, attributes = {}, ...children) {
  const node = document.createElement(tag);
  for (const [name, value] of Object.entries(attributes)) {
    if (value === undefined || value === null || value === false) continue;
    if (name === 'text') node.textContent = value;
    else if (name.startsWith('on')) node.addEventListener(name.slice(2), value);
    else if (name === 'dataset') Object.assign(node.dataset, value);
    else node.setAttribute(name, value === true ? '' : value);
  }
  for (const child of children.flat()) {
    if (child === null || child === undefined) continue;
    node.append(child instanceof Node ? child : String(child));
  }
  return node;
}

const MAX_TREE_ITEMS = 200; // a long array shows its first items, then how many more
const MAX_LEAF_CHARS = 500; // a long string (base64 image data) shows its start

export function jsonTree(value, key = null, open = true) {
  const label = key === null ? null : el('span', { class: 'key', text: `${key}: ` });
  if (value === null || typeof value !== 'object') {
    const kind = value === null ? 'null' : typeof value;
    let text = JSON.stringify(value);
    if (text.length > MAX_LEAF_CHARS) text = `${text.slice(0, MAX_LEAF_CHARS)}… (${text.length} characters)`;
    return el('div', { class: 'leaf' }, label, el('span', { class: `v-${kind}`, text }));
  }
  const entries = Array.isArray(value) ? value.map((v, i) => [i, v]) : Object.entries(value);
  const summary = Array.isArray(value) ? `[${value.length}]` : `{${entries.length}}`;
  const node = el('details', { class: 'branch', open: open && entries.length <= 50 },
    el('summary', {}, label, el('span', { class: 'muted', text: summary })));
  for (const [k, v] of entries.slice(0, MAX_TREE_ITEMS)) node.append(jsonTree(v, k, open));
  if (entries.length > MAX_TREE_ITEMS) {
    node.append(el('div', { class: 'muted', text: `… ${entries.length - MAX_TREE_ITEMS} more` }));
  }
  return node;
}

export function formatRate(count, seconds) {
  return seconds > 0 ? (count / seconds).toFixed(1) : '–';
}

export function formatBytes(bytesPerSecond) {
  if (bytesPerSecond >= 1e6) return `${(bytesPerSecond / 1e6).toFixed(1)} MB/s`;
  if (bytesPerSecond >= 1e3) return `${(bytesPerSecond / 1e3).toFixed(1)} kB/s`;
  return `${bytesPerSecond.toFixed(0)} B/s`;
}

export function showError(target, error) {
  target.replaceChildren(el('div', { class: 'error', text: String(error.message ?? error) }));
}
