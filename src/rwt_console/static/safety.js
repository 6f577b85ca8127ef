// The server's safety envelope (docs/safety.md), on the Server tab: the rules remote clients
// are held to, and the last events (clamps, refusals, rate drops, dead-man stops, approvals),
// from the latched /rwt/safety topic the server publishes (JSON in a std_msgs/String).
import { el } from './ui.js';

export const SAFETY_TOPIC = '/rwt/safety';

function bounds(rule) {
  return Object.entries(rule.bounds ?? {}).map(([field, [min, max]]) => `${field} [${min}, ${max}]`).join(', ');
}

function ruleRow(rule) {
  return el('tr', { dataset: { name: rule.name } },
    el('td', { text: rule.name }),
    el('td', { text: rule.type }),
    el('td', { text: bounds(rule) || '–' }),
    el('td', { text: rule.on_violation }),
    el('td', { text: rule.max_rate_hz ? `${rule.max_rate_hz} Hz` : '–' }),
    el('td', { text: rule.deadman_s ? `${rule.deadman_s} s${rule.commanded ? ' (commanded)' : ''}` : '–' }),
    el('td', { text: rule.approval ? 'yes' : 'no' }));
}

function eventRow(event) {
  const count = event.count > 1 ? ` ×${event.count}` : '';
  const value = event.value === null || event.value === undefined ? '' : String(event.value);
  return el('tr', { dataset: { kind: event.kind } },
    el('td', { text: new Date(event.wall * 1000).toLocaleTimeString() }),
    el('td', { text: `${event.kind}${count}` }),
    el('td', { text: `${event.client} (${event.frontend})` }),
    el('td', { text: event.target }),
    el('td', { text: event.field }),
    el('td', { text: value }),
    el('td', { text: [event.bound, event.detail].filter(Boolean).join(' ') }));
}

function show(status) {
  document.getElementById('safety').hidden = false;
  const calls = [...(status.services ?? []), ...(status.actions ?? [])];
  document.getElementById('safety-calls').textContent = calls.length
    ? `Calls an MCP agent makes only with a person's approval: ${calls.join(', ')}.`
    : '';
  document.querySelector('#safety-rules tbody').replaceChildren(...(status.topics ?? []).map(ruleRow));
  document.querySelector('#safety-events tbody').replaceChildren(...[...(status.events ?? [])].reverse().map(eventRow));
}

// Follow the envelope where the server has one (its topic is in the graph's listing).
export function watchSafety(ros, types) {
  if (!types.has(SAFETY_TOPIC)) return;
  ros.subscribe(SAFETY_TOPIC, types.get(SAFETY_TOPIC), (msg) => {
    try {
      show(JSON.parse(msg.data));
    } catch {
      // not the envelope's JSON: nothing to show
    }
  });
}
