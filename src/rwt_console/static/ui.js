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

const MAX_TREE_ITEMS = 32; // a long array shows its first items, then how many more
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

// Keep parent's children in line with keys (in order), reusing the child of each key
// (data-key): rows a user is pressing are not replaced under the pointer, and only
// changed rows are touched. make(key) builds a child; update(child, key) refreshes it.
export function syncChildren(parent, keys, make, update) {
  const old = new Map([...parent.children].map((child) => [child.dataset.key, child]));
  let at = parent.firstElementChild;
  for (const key of keys) {
    let child = old.get(key);
    if (child) {
      old.delete(key);
      update(child, key);
    } else {
      child = make(key);
      child.dataset.key = key;
    }
    if (child !== at) parent.insertBefore(child, at);
    else at = at.nextElementSibling;
  }
  for (const child of old.values()) child.remove();
}

// A ROS name that may wrap after each '/' and nowhere else (unless one part alone is
// wider than its box): /robot/arm/joint_states, not /robot/arm/joi-nt_states.
export function rosName(name) {
  const node = el('span', { class: 'ros-name' });
  name.split('/').forEach((part, i) => {
    if (i > 0) node.append('/', document.createElement('wbr'));
    node.append(part);
  });
  return node;
}

// The graph filter's test of a name: a part of the name, or a glob with * (any
// characters) and ? (one), as ros2 topic list | grep does; '' matches every name.
export function nameMatcher(filter) {
  const text = filter.trim();
  if (text.includes('*') || text.includes('?')) {
    const escaped = text.replace(/[.+^${}()|[\]\\]/g, '\\$&');
    const pattern = new RegExp(`^${escaped.replace(/\*/g, '.*').replace(/\?/g, '.')}$`);
    return (name) => pattern.test(name);
  }
  return text ? (name) => name.includes(text) : () => true;
}

// A list item or table row a keyboard can reach and choose (Enter or Space).
export function choosable(node, onChoose) {
  node.tabIndex = 0;
  node.setAttribute('role', 'button');
  node.addEventListener('click', onChoose);
  node.addEventListener('keydown', (event) => {
    if (event.key === 'Enter' || event.key === ' ') {
      event.preventDefault();
      onChoose();
    }
  });
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
