// The Teleop tab: geometry_msgs/Twist from the keyboard (W A S D or the arrows) or the
// on-screen pad, as teleop_twist_keyboard sends it, with a dead-man stop: a zero
// Twist as soon as the key or button is released or the page loses the focus.
const REPEAT_MS = 100; // 10 Hz while held, as a joystick teleop publishes
const KEYS = {
  w: [1, 0], ArrowUp: [1, 0], s: [-1, 0], ArrowDown: [-1, 0],
  a: [0, 1], ArrowLeft: [0, 1], d: [0, -1], ArrowRight: [0, -1],
};

export class TeleopView {
  constructor(ros, typeOf) {
    this.ros = ros;
    this.typeOf = typeOf; // topic -> its type in the graph, or undefined
    this.held = null; // [forward, turn] while a key or button is down
    this.timer = null;
    const pad = document.getElementById('teleop-pad');
    pad.addEventListener('keydown', (event) => {
      const motion = KEYS[event.key];
      if (!motion) return;
      event.preventDefault();
      if (!event.repeat) this.go(motion);
    });
    pad.addEventListener('keyup', (event) => {
      if (KEYS[event.key]) this.stop();
    });
    pad.addEventListener('blur', () => this.stop());
    window.addEventListener('blur', () => this.stop());
    document.addEventListener('visibilitychange', () => this.stop());
    for (const button of pad.querySelectorAll('button[data-motion]')) {
      const motion = button.dataset.motion.split(',').map(Number);
      button.addEventListener('pointerdown', () => this.go(motion));
      for (const end of ['pointerup', 'pointerleave', 'pointercancel']) {
        button.addEventListener(end, () => this.stop());
      }
    }
  }

  twist([forward, turn]) {
    const linear = Number(document.getElementById('teleop-linear').value) || 0;
    const angular = Number(document.getElementById('teleop-angular').value) || 0;
    return {
      linear: { x: forward * linear, y: 0, z: 0 },
      angular: { x: 0, y: 0, z: turn * angular },
    };
  }

  send(motion) {
    const topic = document.getElementById('teleop-topic').value || '/cmd_vel';
    const type = this.typeOf(topic) ?? 'geometry_msgs/msg/Twist';
    const state = document.getElementById('teleop-state');
    try {
      this.ros.publish(topic, type, this.twist(motion));
      state.className = 'muted';
      state.textContent = motion[0] || motion[1] ? `moving (${motion.join(', ')})` : 'stopped';
    } catch (error) {
      state.className = 'error';
      state.textContent = error.message;
    }
  }

  go(motion) {
    this.held = motion;
    this.send(motion);
    clearInterval(this.timer);
    this.timer = setInterval(() => this.send(this.held), REPEAT_MS);
  }

  stop() {
    if (this.held === null) return;
    this.held = null;
    clearInterval(this.timer);
    this.timer = null;
    this.send([0, 0]);
  }
}
