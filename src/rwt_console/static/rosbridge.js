// A small rosbridge v2 client for the console (docs/console.md): JSON over one
// WebSocket, the ops the console uses and nothing more. Replies are matched by id.

export class RosbridgeError extends Error {}

export class Rosbridge {
  constructor(url) {
    this.url = url;
    this.socket = null;
    this.nextId = 1;
    this.pending = new Map(); // id -> {resolve, reject, onFeedback}
    this.topics = new Map(); // topic -> Set of handlers
    this.last = new Map(); // topic -> its newest message, for a second handler of the topic
    this.advertised = new Set();
    this.listeners = { close: [], status: [], open: [] };
  }

  on(event, handler) {
    this.listeners[event].push(handler);
  }

  emit(event, value) {
    for (const handler of this.listeners[event]) handler(value);
  }

  connect() {
    return new Promise((resolve, reject) => {
      const socket = new WebSocket(this.url);
      this.socket = socket;
      socket.onopen = () => {
        this.emit('open', this.url);
        resolve();
      };
      socket.onerror = () => reject(new RosbridgeError(`cannot connect to ${this.url}`));
      socket.onclose = (event) => {
        for (const call of this.pending.values()) {
          call.reject(new RosbridgeError(`connection closed (${event.code} ${event.reason})`));
        }
        this.pending.clear();
        this.emit('close', event);
      };
      socket.onmessage = (event) => this.receive(event.data);
    });
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
      this.send({ op: 'subscribe', id: `sub:${topic}`, topic, type, ...options });
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
      this.last.delete(topic);
      if (this.connected) this.send({ op: 'unsubscribe', id: `sub:${topic}`, topic });
    }
  }

  publish(topic, type, msg) {
    if (!this.advertised.has(topic)) {
      this.send({ op: 'advertise', id: `adv:${topic}`, topic, type });
      this.advertised.add(topic);
    }
    this.send({ op: 'publish', topic, msg });
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
    this.send({ op: 'auth', ...fields });
  }

  close() {
    if (this.socket) this.socket.close();
  }
}
