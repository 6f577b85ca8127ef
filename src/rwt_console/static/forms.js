// Forms generated from rosapi typedefs (/rosapi/message_details and friends): one
// input per primitive field, a fieldset per nested message, JSON for arrays.
import { el } from './ui.js';

// Every primitive name rosapi reports: ROS 1's .msg names, and ROS 2's IDL names
// (boolean, octet, float, double; string<N> for a bounded string), see
// rwt_graph/rosapi/typedefs.py.
const BOOL = new Set(['bool', 'boolean']);
const INTEGER = new Set(['byte', 'octet', 'char', 'int8', 'uint8', 'int16', 'uint16', 'int32', 'uint32', 'int64', 'uint64']);
const FLOAT = new Set(['float32', 'float64', 'double', 'float', 'long double']);

// 'string<10>' -> 'string': the bound does not change the input
function baseType(type) {
  const open = type.indexOf('<');
  return open > 0 && !type.includes('/') ? type.slice(0, open) : type;
}
const MAX_DEPTH = 8; // recursive message types stop here (the field becomes JSON)

function parseExample(example, fallback) {
  try {
    return JSON.parse(example);
  } catch {
    return fallback;
  }
}

function zero(type, byType) {
  if (byType.has(type)) return {};
  if (BOOL.has(type)) return false;
  if (INTEGER.has(type) || FLOAT.has(type)) return 0;
  return '';
}

function field(name, rawType, arrayLength, example, byType, depth, path) {
  const type = baseType(rawType);
  const id = `f-${path.join('-')}`;
  const label = el('label', { for: id, text: `${name} `, title: arrayLength >= 0 ? `${rawType}[]` : rawType });
  if (arrayLength >= 0 || (depth >= MAX_DEPTH && byType.has(type))) {
    const input = el('textarea', { id, name: path.join('.'), rows: 2, placeholder: '[] (JSON)' });
    // a fixed-size array (float64[9] covariance) starts with its size, an unbounded one empty
    input.value = arrayLength >= 0 ? JSON.stringify(Array(arrayLength).fill(zero(type, byType))) : '{}';
    const read = () => {
      try {
        return JSON.parse(input.value || (arrayLength >= 0 ? '[]' : '{}'));
      } catch {
        throw new Error(`${path.join('.')}: not valid JSON`);
      }
    };
    return { node: el('div', { class: 'field' }, label, input), read };
  }
  if (byType.has(type)) {
    const inner = messageFields(type, byType, depth + 1, path);
    const node = el('fieldset', { class: 'nested' }, el('legend', { text: `${name} (${type})` }), inner.nodes);
    return { node, read: inner.read };
  }
  if (BOOL.has(type)) {
    const input = el('input', { id, name: path.join('.'), type: 'checkbox' });
    input.checked = example === 'True' || example === 'true';
    return { node: el('div', { class: 'field' }, label, input), read: () => input.checked };
  }
  if (INTEGER.has(type) || FLOAT.has(type)) {
    const input = el('input', { id, name: path.join('.'), type: 'number', step: FLOAT.has(type) ? 'any' : '1' });
    input.value = String(parseExample(example, 0));
    const read = () => {
      const value = Number(input.value || 0);
      if (!Number.isFinite(value) || (INTEGER.has(type) && !Number.isInteger(value))) {
        throw new Error(`${path.join('.')}: ${input.value} is not a valid ${type}`);
      }
      return value;
    };
    return { node: el('div', { class: 'field' }, label, input), read };
  }
  // string, wstring and anything unknown: text
  const input = el('input', { id, name: path.join('.'), type: 'text' });
  input.value = example && example !== '{}' ? example : '';
  return { node: el('div', { class: 'field' }, label, input), read: () => input.value };
}

function messageFields(type, byType, depth, path) {
  const def = byType.get(type);
  const fields = def.fieldnames.map((name, i) =>
    [name, field(name, def.fieldtypes[i], def.fieldarraylen[i], def.examples[i], byType, depth, [...path, name])]);
  return {
    nodes: fields.map(([, f]) => f.node),
    read: () => Object.fromEntries(fields.map(([name, f]) => [name, f.read()])),
  };
}

// typedefs: the list rosapi answers, the root type first. Returns {node, read()}:
// read() gives the message as a dict or throws an Error naming the bad field.
export function typedefForm(typedefs, prefix) {
  if (!typedefs || typedefs.length === 0) {
    return { node: el('p', { class: 'muted', text: 'no fields' }), read: () => ({}) };
  }
  const byType = new Map(typedefs.map((def) => [def.type, def]));
  const root = messageFields(typedefs[0].type, byType, 0, [prefix]);
  return { node: el('div', { class: 'form-fields' }, root.nodes), read: root.read };
}
