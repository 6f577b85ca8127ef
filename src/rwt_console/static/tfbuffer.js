// The transforms of /tf and /tf_static, newest per child frame, shared by the TF tree
// and the 2D view (one subscription each, so a latched /tf_static reaches both); a
// frame is resolved into another through their common root, as tf2's lookupTransform.

const IDENTITY = { translation: [0, 0, 0], rotation: [0, 0, 0, 1] };

export class TfBuffer {
  constructor(ros) {
    this.ros = ros;
    this.frames = new Map(); // child -> {parent, translation: [x, y, z], rotation: [x, y, z, w], isStatic}
    this.listeners = new Set();
    this.subscribed = false;
  }

  start(types) {
    if (this.subscribed) return;
    this.subscribed = true;
    const type = types.get('/tf') ?? 'tf2_msgs/msg/TFMessage';
    this.ros.subscribe('/tf', type, (msg) => this.add(msg, false), { throttle_rate: 100 });
    this.ros.subscribe('/tf_static', types.get('/tf_static') ?? type, (msg) => this.add(msg, true));
  }

  onChange(listener) {
    this.listeners.add(listener);
  }

  add(msg, isStatic) {
    for (const transform of msg.transforms ?? []) {
      const t = transform.transform ?? {};
      const v = t.translation ?? {};
      const q = t.rotation ?? {};
      this.frames.set(frameName(transform.child_frame_id), {
        parent: frameName(transform.header?.frame_id),
        translation: [v.x ?? 0, v.y ?? 0, v.z ?? 0],
        rotation: [q.x ?? 0, q.y ?? 0, q.z ?? 0, q.w ?? 1],
        isStatic,
      });
    }
    for (const listener of this.listeners) listener();
  }

  // Every frame named so far, children and parents.
  names() {
    const names = new Set(this.frames.keys());
    for (const { parent } of this.frames.values()) names.add(parent);
    return names;
  }

  // The pose of `frame` in `target` ({translation, rotation}), or null when the two
  // are not in one tree (or a cycle is on the way).
  lookup(target, frame) {
    const a = this.toRoot(frameName(target));
    const b = this.toRoot(frameName(frame));
    if (!a || !b || a.root !== b.root) return null;
    return compose(invert(a.pose), b.pose);
  }

  toRoot(frame) {
    let pose = IDENTITY;
    let at = frame;
    const seen = new Set();
    while (this.frames.has(at)) {
      if (seen.has(at)) return null;
      seen.add(at);
      const step = this.frames.get(at);
      pose = compose(step, pose);
      at = step.parent;
    }
    return { root: at, pose };
  }
}

// tf's frame ids have no leading '/' (ROS 1's had one).
export function frameName(frame) {
  return String(frame ?? '').replace(/^\//, '');
}

// The rotation about z of a quaternion [x, y, z, w], in radians.
export function yawOf([x, y, z, w]) {
  return Math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z));
}

function multiply([ax, ay, az, aw], [bx, by, bz, bw]) {
  return [
    aw * bx + ax * bw + ay * bz - az * by,
    aw * by - ax * bz + ay * bw + az * bx,
    aw * bz + ax * by - ay * bx + az * bw,
    aw * bw - ax * bx - ay * by - az * bz,
  ];
}

function rotate(q, [x, y, z]) {
  const [rx, ry, rz] = multiply(multiply(q, [x, y, z, 0]), [-q[0], -q[1], -q[2], q[3]]);
  return [rx, ry, rz];
}

// a then b: b's pose given in a's frame, a's in its parent's.
export function compose(a, b) {
  const moved = rotate(a.rotation, b.translation);
  return {
    translation: moved.map((value, i) => value + a.translation[i]),
    rotation: multiply(a.rotation, b.rotation),
  };
}

function invert({ translation, rotation }) {
  const conjugate = [-rotation[0], -rotation[1], -rotation[2], rotation[3]];
  return { translation: rotate(conjugate, translation).map((value) => -value), rotation: conjugate };
}
