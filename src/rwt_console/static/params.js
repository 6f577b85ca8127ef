// The Parameters tab: every parameter (/rosapi/get_param_names, /rosapi/get_param)
// with an input that fits its JSON value, and a Set button per row
// (/rosapi/set_param), as rqt_reconfigure edits them. Values travel as JSON text
// both ways, as rosapi has them; a refusal (read-only, a type change, --params-glob)
// is shown beside the row's button in the server's words.
import { el, nameMatcher, rosName, syncChildren } from './ui.js';

const MAX_PARAMS = 500; // values are read one call each

// The kind of input a value's JSON text asks for. The text, not the parsed value,
// tells an integer from a float: JSON.parse('1.0') is 1, but the parameter is a double.
export function paramKind(text) {
  let value;
  try {
    value = JSON.parse(text);
  } catch {
    return 'json';
  }
  if (typeof value === 'boolean') return 'bool';
  if (typeof value === 'number') return /^-?\d+$/.test(text.trim()) ? 'int' : 'float';
  if (typeof value === 'string') return 'string';
  return 'json'; // arrays, objects (ROS 1 namespaces) and null
}

// The JSON text to send for what the input holds, or an Error naming what is wrong.
// A float stays a float (2 -> 2.0), so a double parameter does not become an integer.
export function inputToJson(kind, input) {
  if (kind === 'bool') return JSON.stringify(input.checked);
  if (kind === 'string') return JSON.stringify(input.value);
  const text = input.value.trim();
  if (kind === 'int') {
    if (!/^-?\d+$/.test(text)) throw new Error(`${text || '(empty)'} is not an integer`);
    return text; // as typed: an int64 beyond 2^53 keeps its digits
  }
  if (kind === 'float') {
    const value = Number(text);
    if (text === '' || !Number.isFinite(value)) throw new Error(`${text || '(empty)'} is not a number`);
    return Number.isInteger(value) ? value.toFixed(1) : String(value);
  }
  try {
    JSON.parse(text);
  } catch {
    throw new Error('not valid JSON');
  }
  return text;
}

function makeInput(kind, name) {
  const label = `value of ${name}`;
  if (kind === 'bool') return el('input', { type: 'checkbox', 'aria-label': label });
  if (kind === 'int') return el('input', { type: 'number', step: '1', 'aria-label': label });
  if (kind === 'float') return el('input', { type: 'number', step: 'any', 'aria-label': label });
  if (kind === 'string') return el('input', { type: 'text', 'aria-label': label });
  return el('textarea', { rows: 2, 'aria-label': `${label} (JSON)` });
}

export class ParamsView {
  constructor(ros) {
    this.ros = ros;
    this.body = document.querySelector('#param-editor tbody');
    this.filter = document.getElementById('graph-filter');
    this.filter.addEventListener('input', () => this.applyFilter());
    // Reload reads every value again, over what was typed and not set
    document.getElementById('param-reload').addEventListener('click', () => this.refresh({ discard: true }));
  }

  // Lists the parameters and reads their values; discard: also over edited inputs.
  async refresh({ discard = false } = {}) {
    const count = document.getElementById('param-editor-count');
    try {
      const { names } = await this.ros.callService('/rosapi/get_param_names');
      const shown = names.slice(0, MAX_PARAMS);
      syncChildren(this.body, shown, (name) => this.makeRow(name), () => {});
      count.textContent = names.length > MAX_PARAMS ? `${MAX_PARAMS} of ${names.length}` : `${names.length}`;
      this.applyFilter();
      await Promise.all(shown.map((name) => this.load(this.rowOf(name), discard)));
    } catch (error) {
      count.textContent = `cannot list them: ${error.message}`;
    }
  }

  rowOf(name) {
    return [...this.body.children].find((row) => row.dataset.key === name);
  }

  applyFilter() {
    const matches = nameMatcher(this.filter.value);
    for (const row of this.body.children) row.hidden = !matches(row.dataset.name);
  }

  makeRow(name) {
    const set = el('button', { type: 'button', text: 'Set', 'aria-label': `set ${name}` });
    const result = el('span', { class: 'muted', role: 'status', 'aria-live': 'polite' });
    const row = el('tr', { dataset: { name } },
      el('td', {}, rosName(name)), el('td', { class: 'param-value' }), el('td', {}, set, ' ', result));
    set.addEventListener('click', () => this.set(row));
    return row;
  }

  // Read the parameter again; an input the user is editing (changed, not yet set) keeps
  // what they typed, unless discard or the value's kind changed under it.
  async load(row, discard = false) {
    if (!row) return;
    const { name } = row.dataset;
    let text;
    try {
      ({ value: text } = await this.ros.callService('/rosapi/get_param', { name }));
    } catch (error) {
      this.say(row, `cannot read it: ${error.message}`, true);
      return;
    }
    const kind = paramKind(text);
    const cell = row.querySelector('.param-value');
    let input = cell.firstElementChild;
    if (!input || row.dataset.kind !== kind) {
      input = makeInput(kind, name);
      input.addEventListener('input', () => {
        row.dataset.edited = 'true';
      });
      input.addEventListener('keydown', (event) => {
        // Enter sets (Ctrl+Enter in a JSON area, where Enter is a new line)
        if (event.key === 'Enter' && (input.tagName !== 'TEXTAREA' || event.ctrlKey)) {
          event.preventDefault();
          this.set(row);
        }
      });
      cell.replaceChildren(input);
      row.dataset.kind = kind;
    } else if (row.dataset.edited && !discard) {
      return;
    }
    const value = kind === 'json' ? null : JSON.parse(text);
    if (kind === 'bool') input.checked = value;
    else if (kind === 'string') input.value = value;
    else input.value = text;
    row.dataset.value = text;
    delete row.dataset.edited;
  }

  async set(row) {
    const { name, kind } = row.dataset;
    const input = row.querySelector('.param-value').firstElementChild;
    if (!input) return; // its value is still being read
    let value;
    try {
      value = inputToJson(kind, input);
    } catch (error) {
      this.say(row, error.message, true);
      return;
    }
    this.say(row, 'setting…', false);
    try {
      // ROS 2's rosapi answers a refusal with successful: false and a reason; ROS 1's
      // fails the call (rwt_graph/rosapi/paramsrv.py)
      const reply = await this.ros.callService('/rosapi/set_param', { name, value });
      if (reply.successful === false) {
        this.say(row, `refused: ${reply.reason}`, true);
        return;
      }
      await this.load(row, true);
      this.say(row, `set at ${new Date().toLocaleTimeString()}`, false);
    } catch (error) {
      this.say(row, `refused: ${error.message}`, true);
    }
  }

  say(row, text, isError) {
    const result = row.querySelector('[role=status]');
    result.className = isError ? 'error' : 'muted';
    result.textContent = text;
  }
}
