// The 2D view: a nav_msgs/OccupancyGrid on a canvas (its resolution and origin
// honoured, y up), the TF frames resolved into the map's frame (an axis pair and the
// name each) and the robot's pose as an arrow, from a TF frame or a PoseStamped
// topic. Drag or the arrow keys pan; the wheel or + and - zoom; 0 fits the map.
import { compose, frameName, yawOf } from './tfbuffer.js';

const MAP_TYPE = 'nav_msgs/msg/OccupancyGrid';
const POSE_TYPE = 'geometry_msgs/msg/PoseStamped';
const FIT = 0.9; // a fitted map fills 90% of the canvas
const ZOOM_STEP = 1.25; // per + or -, and per 100 px of wheel
const PAN_PX = 40; // per arrow key
const AXIS_PX = 18;
const ARROW = '#e000e0';
const UNKNOWN = 205; // map_server's grey for unknown cells

export class MapView {
  constructor(ros, tf) {
    this.ros = ros;
    this.tf = tf;
    this.canvas = document.getElementById('map-canvas');
    this.info = document.getElementById('map-info');
    this.error = document.getElementById('map-error');
    this.mapTopic = document.getElementById('map-topic');
    this.poseKind = document.getElementById('map-pose-kind');
    this.poseName = document.getElementById('map-pose');
    this.grid = null; // {frame, image (a canvas, a cell a pixel), info}
    this.pose = null; // the PoseStamped last received, when the pose comes from a topic
    this.view = { x: 0, y: 0, scale: 50 }; // the map point at the canvas' centre, px per m
    this.fitted = false;
    this.started = false;
    this.active = false;
    this.frame = 0;
    this.stopMap = null;
    this.stopPose = null;
    this.types = new Map();
    tf.onChange(() => this.schedule());
    this.mapTopic.addEventListener('change', () => this.subscribeMap());
    this.poseKind.addEventListener('change', () => this.subscribePose());
    this.poseName.addEventListener('change', () => this.subscribePose());
    document.getElementById('map-fit').addEventListener('click', () => this.fit());
    ros.on('status', (message) => {
      // a refused subscription (a wrong type, a topic not allowed) is said here
      if (message.level === 'error' && [this.mapTopic.value, this.poseName.value].some((t) => message.id === `sub:${t}`)) {
        this.error.textContent = message.msg;
      }
    });
    this.wireInput();
  }

  setActive(active, types) {
    this.active = active;
    this.types = types;
    if (!active) return;
    if (!this.started) {
      this.started = true;
      this.tf.start(types);
      this.subscribeMap();
      this.subscribePose();
    }
    this.schedule();
  }

  subscribeMap() {
    if (this.stopMap) this.stopMap();
    this.stopMap = null;
    this.grid = null;
    this.fitted = false;
    this.error.textContent = '';
    const topic = this.mapTopic.value.trim();
    if (!topic) return;
    try {
      // a map is latched (transient local): it comes at once, however late the page subscribes
      this.stopMap = this.ros.subscribe(topic, this.types.get(topic) ?? MAP_TYPE, (msg) => this.receiveMap(msg));
    } catch (error) {
      this.error.textContent = `cannot subscribe to ${topic}: ${error.message}`;
    }
    this.schedule();
  }

  subscribePose() {
    if (this.stopPose) this.stopPose();
    this.stopPose = null;
    this.pose = null;
    const topic = this.poseName.value.trim();
    if (this.poseKind.value === 'topic' && topic) {
      try {
        this.stopPose = this.ros.subscribe(topic, this.types.get(topic) ?? POSE_TYPE, (msg) => {
          this.pose = msg;
          this.schedule();
        });
      } catch (error) {
        this.error.textContent = `cannot subscribe to ${topic}: ${error.message}`;
      }
    }
    this.schedule();
  }

  receiveMap(msg) {
    try {
      this.grid = gridImage(msg);
      this.error.textContent = '';
    } catch (error) {
      this.grid = null;
      this.error.textContent = `${this.mapTopic.value}: ${error.message}`;
    }
    if (this.grid && !this.fitted) this.fit();
    this.schedule();
  }

  // The whole map in view, centred.
  fit() {
    if (!this.grid) return;
    const corners = this.grid.corners;
    const xs = corners.map(([x]) => x);
    const ys = corners.map(([, y]) => y);
    const width = Math.max(...xs) - Math.min(...xs);
    const height = Math.max(...ys) - Math.min(...ys);
    this.view = {
      x: (Math.max(...xs) + Math.min(...xs)) / 2,
      y: (Math.max(...ys) + Math.min(...ys)) / 2,
      scale: FIT * Math.min(this.canvas.width / width, this.canvas.height / height),
    };
    this.fitted = true;
    this.schedule();
  }

  // Pixels of the canvas, from a pointer's CSS pixels (inside its border; the canvas
  // may be shown smaller than its pixels).
  canvasPoint(event) {
    const { canvas } = this;
    const box = canvas.getBoundingClientRect();
    return [(event.clientX - box.left - canvas.clientLeft) * (canvas.width / canvas.clientWidth),
      (event.clientY - box.top - canvas.clientTop) * (canvas.height / canvas.clientHeight)];
  }

  pan(dx, dy) {
    this.view.x -= dx / this.view.scale;
    this.view.y += dy / this.view.scale;
    this.schedule();
  }

  // Zoom by `factor` keeping the map point under canvas pixel (px, py) where it is.
  zoom(factor, px = this.canvas.width / 2, py = this.canvas.height / 2) {
    const [x, y] = this.toMap(px, py);
    this.view.scale = Math.min(1e5, Math.max(1e-3, this.view.scale * factor));
    const [x2, y2] = this.toMap(px, py);
    this.view.x += x - x2;
    this.view.y += y - y2;
    this.schedule();
  }

  toMap(px, py) {
    const { x, y, scale } = this.view;
    return [x + (px - this.canvas.width / 2) / scale, y - (py - this.canvas.height / 2) / scale];
  }

  toCanvas(x, y) {
    const { scale } = this.view;
    return [this.canvas.width / 2 + (x - this.view.x) * scale, this.canvas.height / 2 - (y - this.view.y) * scale];
  }

  wireInput() {
    const canvas = this.canvas;
    let drag = null;
    canvas.addEventListener('pointerdown', (event) => {
      canvas.focus();
      canvas.setPointerCapture(event.pointerId);
      drag = this.canvasPoint(event);
    });
    canvas.addEventListener('pointermove', (event) => {
      if (!drag) return;
      const at = this.canvasPoint(event);
      this.pan(at[0] - drag[0], at[1] - drag[1]);
      drag = at;
    });
    const stop = () => {
      drag = null;
    };
    canvas.addEventListener('pointerup', stop);
    canvas.addEventListener('pointercancel', stop);
    canvas.addEventListener('wheel', (event) => {
      event.preventDefault();
      const pixels = event.deltaY * (event.deltaMode === 1 ? 40 : 1); // lines, on some mice
      this.zoom(ZOOM_STEP ** (-pixels / 100), ...this.canvasPoint(event));
    }, { passive: false });
    canvas.addEventListener('keydown', (event) => {
      const pan = { ArrowLeft: [PAN_PX, 0], ArrowRight: [-PAN_PX, 0], ArrowUp: [0, PAN_PX], ArrowDown: [0, -PAN_PX] }[event.key];
      if (pan) this.pan(...pan);
      else if (event.key === '+' || event.key === '=') this.zoom(ZOOM_STEP);
      else if (event.key === '-') this.zoom(1 / ZOOM_STEP);
      else if (event.key === '0') this.fit();
      else return;
      event.preventDefault();
    });
  }

  schedule() {
    if (!this.active || this.frame) return;
    this.frame = requestAnimationFrame(() => this.draw());
  }

  draw() {
    this.frame = 0;
    const ctx = this.canvas.getContext('2d');
    const { width, height } = this.canvas;
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.fillStyle = '#eef0f3';
    ctx.fillRect(0, 0, width, height);
    const fixed = this.grid ? this.grid.frame : 'map';
    if (this.grid) {
      const { scale } = this.view;
      const [ox, oy] = this.toCanvas(0, 0);
      const { origin, yaw, resolution } = this.grid;
      ctx.setTransform(scale, 0, 0, -scale, ox, oy); // map metres, y up
      ctx.translate(origin[0], origin[1]);
      ctx.rotate(yaw);
      ctx.scale(resolution, resolution);
      ctx.imageSmoothingEnabled = false; // a cell is a square, not a blur
      ctx.drawImage(this.grid.image, 0, 0); // row 0 at the origin, rows going up
      ctx.setTransform(1, 0, 0, 1, 0, 0);
    }
    const lines = [];
    for (const frame of [...this.tf.names()].sort()) {
      const pose = this.tf.lookup(fixed, frame);
      if (pose) this.drawAxes(ctx, frame, pose);
    }
    const robot = this.robotPose(fixed);
    if (robot) {
      this.drawArrow(ctx, robot);
      lines.push(`robot ${robot.name} at (${robot.x.toFixed(2)}, ${robot.y.toFixed(2)}) m, `
        + `heading ${(robot.yaw * 180 / Math.PI).toFixed(0)}° in ${fixed}`);
    } else if (this.poseName.value.trim()) {
      lines.push(`no pose of ${this.poseName.value.trim()} in ${fixed} yet`);
    }
    if (this.grid) {
      const { info } = this.grid;
      lines.unshift(`map ${info.width} × ${info.height} cells of ${this.grid.resolution} m, origin `
        + `(${this.grid.origin[0].toFixed(2)}, ${this.grid.origin[1].toFixed(2)}) in ${fixed}`);
    } else {
      lines.unshift(`no map on ${this.mapTopic.value} yet`);
    }
    const text = lines.join('; ');
    if (this.info.textContent !== text) this.info.textContent = text;
  }

  // {name, x, y, yaw} in the fixed frame, or null.
  robotPose(fixed) {
    const name = this.poseName.value.trim();
    if (!name) return null;
    let pose;
    if (this.poseKind.value === 'topic') {
      if (!this.pose) return null;
      const p = this.pose.pose ?? {};
      const q = p.orientation ?? {};
      const at = this.tf.lookup(fixed, this.pose.header?.frame_id || fixed);
      if (!at) return null;
      pose = compose(at, { translation: [p.position?.x ?? 0, p.position?.y ?? 0, p.position?.z ?? 0],
        rotation: [q.x ?? 0, q.y ?? 0, q.z ?? 0, q.w ?? 1] });
    } else {
      pose = this.tf.lookup(fixed, name);
      if (!pose) return null;
    }
    return { name, x: pose.translation[0], y: pose.translation[1], yaw: yawOf(pose.rotation) };
  }

  drawAxes(ctx, frame, pose) {
    const [px, py] = this.toCanvas(pose.translation[0], pose.translation[1]);
    const yaw = yawOf(pose.rotation);
    ctx.lineWidth = 2;
    for (const [angle, colour] of [[yaw, '#d03030'], [yaw + Math.PI / 2, '#20a040']]) {
      ctx.strokeStyle = colour;
      ctx.beginPath();
      ctx.moveTo(px, py);
      ctx.lineTo(px + AXIS_PX * Math.cos(angle), py - AXIS_PX * Math.sin(angle));
      ctx.stroke();
    }
    ctx.fillStyle = '#1f3a5f';
    ctx.font = '11px sans-serif';
    ctx.fillText(frame, px + 4, py + 13);
  }

  drawArrow(ctx, { x, y, yaw }) {
    const [px, py] = this.toCanvas(x, y);
    ctx.save();
    ctx.translate(px, py);
    ctx.rotate(-yaw); // the canvas' y is down
    ctx.fillStyle = ARROW;
    ctx.strokeStyle = ARROW;
    ctx.beginPath();
    ctx.arc(0, 0, 6, 0, 2 * Math.PI);
    ctx.fill();
    ctx.lineWidth = 4;
    ctx.beginPath();
    ctx.moveTo(0, 0);
    ctx.lineTo(16, 0);
    ctx.stroke();
    ctx.beginPath();
    ctx.moveTo(28, 0);
    ctx.lineTo(14, -8);
    ctx.lineTo(14, 8);
    ctx.closePath();
    ctx.fill();
    ctx.restore();
  }
}

// An OccupancyGrid as a canvas with a pixel a cell (row 0 first): unknown (-1) grey,
// 0 (free) white to 100 (occupied) black.
// Raises an Error naming what is wrong when the message is not a usable grid.
export function gridImage(msg) {
  const info = msg.info ?? {};
  const { width, height, resolution } = info;
  if (!(width > 0 && height > 0 && resolution > 0)) {
    throw new Error(`not a map: width ${width}, height ${height}, resolution ${resolution}`);
  }
  let cells = msg.data ?? [];
  if (typeof cells === 'string') cells = Int8Array.from(atob(cells), (c) => c.charCodeAt(0)); // base64
  if (cells.length !== width * height) {
    throw new Error(`the map has ${cells.length} cells, not width × height = ${width * height}`);
  }
  const image = document.createElement('canvas');
  image.width = width;
  image.height = height;
  const ctx = image.getContext('2d');
  const pixels = ctx.createImageData(width, height);
  const rgba = pixels.data; // written in place: a 4000 x 4000 map is 16 million cells
  for (let i = 0; i < cells.length; i += 1) {
    const value = cells[i];
    const grey = value >= 0 && value <= 100 ? Math.round(255 * (1 - value / 100)) : UNKNOWN;
    rgba[4 * i] = grey;
    rgba[4 * i + 1] = grey;
    rgba[4 * i + 2] = grey;
    rgba[4 * i + 3] = 255;
  }
  ctx.putImageData(pixels, 0, 0);
  const position = info.origin?.position ?? {};
  const q = info.origin?.orientation ?? {};
  const yaw = yawOf([q.x ?? 0, q.y ?? 0, q.z ?? 0, q.w ?? 1]);
  const origin = [position.x ?? 0, position.y ?? 0];
  const corners = [[0, 0], [width, 0], [0, height], [width, height]].map(([c, r]) => [
    origin[0] + resolution * (c * Math.cos(yaw) - r * Math.sin(yaw)),
    origin[1] + resolution * (c * Math.sin(yaw) + r * Math.cos(yaw)),
  ]);
  return { frame: frameName(msg.header?.frame_id) || 'map', image, info, resolution, origin, yaw, corners };
}
