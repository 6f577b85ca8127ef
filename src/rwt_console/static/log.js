// The Log tab: /rosout as `ros2 topic echo /rosout` shows it, newest first, with a
// level filter and a search; the server's own warnings to this page are on the
// Server tab. At most MAX_ENTRIES are kept.
import { el } from './ui.js';

const MAX_ENTRIES = 500;
// ROS 2 (rcl_interfaces/msg/Log) levels, and ROS 1's (rosgraph_msgs/Log) bits
const ROS2_LEVELS = { 10: 'debug', 20: 'info', 30: 'warn', 40: 'error', 50: 'fatal' };
const ROS1_LEVELS = { 1: 'debug', 2: 'info', 4: 'warn', 8: 'error', 16: 'fatal' };
const ORDER = ['debug', 'info', 'warn', 'error', 'fatal'];

export class LogView {
  constructor(ros) {
    this.ros = ros;
    this.started = false;
    this.list = document.getElementById('rosout-log');
    this.level = document.getElementById('log-level');
    this.search = document.getElementById('log-search');
    for (const input of [this.level, this.search]) input.addEventListener('input', () => this.applyFilter());
  }

  start(types) {
    if (this.started) return;
    this.started = true;
    const type = types.get('/rosout') ?? 'rcl_interfaces/msg/Log';
    const levels = type.startsWith('rosgraph_msgs') ? ROS1_LEVELS : ROS2_LEVELS;
    this.ros.subscribe('/rosout', type, (msg) => this.add(msg, levels));
  }

  add(msg, levels) {
    const level = levels[msg.level] ?? String(msg.level);
    const stamp = msg.stamp ?? msg.header?.stamp ?? {};
    const seconds = (stamp.sec ?? stamp.secs ?? 0) + (stamp.nanosec ?? stamp.nsecs ?? 0) / 1e9;
    const text = `${new Date(seconds * 1000).toLocaleTimeString()} [${level}] ${msg.name}: ${msg.msg}`;
    const item = el('li', { class: `log-${level}`, dataset: { level }, text });
    this.list.prepend(item);
    while (this.list.children.length > MAX_ENTRIES) this.list.lastChild.remove();
    this.show(item);
  }

  show(item) {
    const least = ORDER.indexOf(this.level.value);
    const wanted = this.search.value.trim().toLowerCase();
    const rank = ORDER.indexOf(item.dataset.level);
    item.hidden = rank < least || (wanted !== '' && !item.textContent.toLowerCase().includes(wanted));
  }

  applyFilter() {
    for (const item of this.list.children) this.show(item);
  }
}
