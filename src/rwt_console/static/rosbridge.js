// A small rosbridge v2 client for the console (docs/console.md): JSON over one
// WebSocket, the ops the console uses and nothing more. Replies are matched by id.
// Given `webrtc` (the server's http(s) origin), the WebSocket is the `rosbridge` data
// channel instead (datachannel.js, docs/webrtc.md).

import { DataChannelSocket } from './datachannel.js';

export class RosbridgeError extends Error {}

export class Rosbridge {
  constructor(url, { webrtc = null } = {}) {
    this.url = url;
    this.webrtc = webrtc;
    this.socket = null;
    this.nextId = 1;
    this.pending = new Map(); // id -> {resolve, reject, onFeedback}
    this.topics = new Map(); // topic -> Set of handlers
    this.last = new Map(); // topic -> its newest message, for a second handler of the topic
    this.advertised = new Set();
    this.subscribed = new Map(); // topic -> the subscribe op, sent again after a reconnect
    this.listeners = { close: [], status: [], open: [], reconnecting: [] };
    this.auth = null; // the auth op's fields, sent again on each new socket
    this.retries = 0;
    this.closing = false;
  }

  on(event, handler) {
    this.listeners[event].push(handler);
  }

  emit(event, value) {
    for (const handler of this.listeners[event]) handler(value);
  }

  // The first connection; later drops reconnect by themselves once reconnect() is on.
  connect() {
    return new Promise((resolve, reject) => {
      const socket = this.open();
      socket.onopen = () => {
        this.emit('open', this.url);
        resolve();
      };
      socket.onerror = () => reject(new RosbridgeError(`cannot connect to ${this.url}`));
    });
  }

  open() {
    const socket = this.webrtc ? new DataChannelSocket(this.webrtc) : new WebSocket(this.url);
    this.socket = socket;
    socket.onclose = (event) => {
      for (const call of this.pending.values()) {
        call.reject(new RosbridgeError(`connection closed (${event.code} ${event.reason})`));
      }
      this.pending.clear();
      this.emit('close', event);
      if (this.reconnecting && !this.closing) this.scheduleReconnect();
    };
    socket.onmessage = (event) => this.receive(event.data);
    return socket;
  }

  // After a drop: try again after a growing delay with jitter (0.5 s doubling to at
  // most 30 s, times 0.5-1.5, so that a server's clients do not all come back at
  // once); on success the auth op and every subscription go again.
  reconnect() {
    this.reconnecting = true;
  }

  scheduleReconnect() {
    const delay = Math.min(30000, 500 * 2 ** this.retries) * (0.5 + Math.random());
    this.retries += 1;
    this.emit('reconnecting', delay);
    setTimeout(() => {
      const socket = this.open();
      socket.onopen = () => {
        this.retries = 0;
        if (this.auth) this.send({ op: 'auth', ...this.auth });
        this.advertised.clear();
        for (const op of this.subscribed.values()) this.send(op);
        this.emit('open', this.url);
      };
    }, delay);
  }

  get connected() {
    return this.socket !== null && this.socket.readyState === WebSocket.OPEN;
  }

  send(op) {
    if (!this.connected) throw new RosbridgeError('not connected');
    this.socket.send(JSON.stringify(op));
  }

  id(prefix) {
    return `${prefix}:${this.nextId++}`;
  }

  receive(text) {
    let message;
    try {
      message = JSON.parse(text);
    } catch {
      return; // the console asks for JSON only; anything else is not for it
    }
    switch (message.op) {
      case 'publish': {
        const handlers = this.topics.get(message.topic);
        if (!handlers) break;
        this.last.set(message.topic, message.msg);
        for (const handler of handlers) handler(message.msg, text.length);
        break;
      }
      case 'service_response': {
        const call = this.take(message.id);
        if (!call) break;
        if (message.result === false) call.reject(new RosbridgeError(String(message.values)));
        else call.resolve(message.values ?? {});
        break;
      }
      case 'action_feedback': {
        const goal = this.pending.get(message.id);
        if (goal && goal.onFeedback) goal.onFeedback(message.values);
        break;
      }
      case 'action_result': {
        const goal = this.take(message.id);
        if (goal) goal.resolve({ status: message.status, result: message.result, values: message.values });
        break;
      }
      case 'status': {
        if (message.id && message.id.startsWith('adv:') && message.level === 'error') {
          this.advertised.delete(message.id.slice(4)); // refused: advertise again next time
        }
        this.emit('status', message);
        if (message.id && (message.level === 'error')) {
          const call = this.take(message.id);
          if (call) call.reject(new RosbridgeError(message.msg));
        }
        break;
      }
      default:
        break;
    }
  }

  take(id) {
    const call = this.pending.get(id);
    this.pending.delete(id);
    return call;
  }

  callService(service, args = {}) {
    const id = this.id('call');
    return new Promise((resolve, reject) => {
      this.pending.set(id, { resolve, reject });
      try {
        this.send({ op: 'call_service', id, service, args });
      } catch (error) {
        this.pending.delete(id);
        reject(error);
      }
    });
  }

  subscribe(topic, type, handler, options = {}) {
    let handlers = this.topics.get(topic);
    if (!handlers) {
      handlers = new Set();
      this.topics.set(topic, handlers);
      const op = { op: 'subscribe', id: `sub:${topic}`, topic, type, ...options };
      this.subscribed.set(topic, op);
      this.send(op);
    } else if (this.last.has(topic)) {
      // one subscription per topic: a latched message came only once, so replay the newest
      handler(this.last.get(topic), 0, true);
    }
    handlers.add(handler);
    return () => this.unsubscribe(topic, handler);
  }

  unsubscribe(topic, handler) {
    const handlers = this.topics.get(topic);
    if (!handlers) return;
    handlers.delete(handler);
    if (handlers.size === 0) {
      this.topics.delete(topic);
      this.subscribed.delete(topic);
      this.last.delete(topic);
      if (this.connected) this.send({ op: 'unsubscribe', id: `sub:${topic}`, topic });
    }
  }

  // Returns the ids of the ops sent: a refusal comes back as an error status
  // carrying one of them (errorFor), success as nothing.
  publish(topic, type, msg) {
    const ids = [];
    if (!this.advertised.has(topic)) {
      const id = `adv:${topic}`;
      this.send({ op: 'advertise', id, topic, type });
      this.advertised.add(topic);
      ids.push(id);
    }
    const id = this.id('pub');
    this.send({ op: 'publish', id, topic, msg });
    ids.push(id);
    return ids;
  }

  // The first error status naming one of ids within ms, or null: how an op that
  // has no reply (advertise, publish) learns that the server refused it.
  errorFor(ids, ms) {
    const wanted = new Set(ids);
    return new Promise((resolve) => {
      const handler = (message) => {
        if (message.level === 'error' && wanted.has(message.id)) done(message);
      };
      const done = (message) => {
        clearTimeout(timer);
        this.listeners.status = this.listeners.status.filter((h) => h !== handler);
        resolve(message);
      };
      const timer = setTimeout(() => done(null), ms);
      this.on('status', handler);
    });
  }

  setLevel(level) {
    this.send({ op: 'set_level', level });
  }

  sendActionGoal(action, actionType, args, onFeedback) {
    const id = this.id('goal');
    const done = new Promise((resolve, reject) => {
      this.pending.set(id, { resolve, reject, onFeedback });
      try {
        this.send({ op: 'send_action_goal', id, action, action_type: actionType, args, feedback: true });
      } catch (error) {
        this.pending.delete(id);
        reject(error);
      }
    });
    return { id, done, cancel: () => this.send({ op: 'cancel_action_goal', id, action }) };
  }

  authenticate(fields) {
    this.auth = fields;
    this.send({ op: 'auth', ...fields });
  }

  close() {
    this.closing = true;
    if (this.socket) this.socket.close();
  }
}
