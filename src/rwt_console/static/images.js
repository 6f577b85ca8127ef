// Image topics through the video server (docs/video.md): MJPEG in an <img>, VP8 in
// a muted <video> started with play() (Chromium's autoplay policy), with a play
// button when the browser refuses anyway. When the server asks for auth, each
// stream URL carries a short-lived token from /rwt/video_token (docs/video.md).
import { el } from './ui.js';

const IMAGE_TYPES = new Set(['sensor_msgs/msg/Image', 'sensor_msgs/Image']);

export function videoBase(config) {
  if (!config.video) return null;
  return `http://${location.hostname}:${config.video.port}`;
}

export class ImagesView {
  constructor(config, ros) {
    this.base = videoBase(config);
    this.ros = ros;
    this.needsToken = Boolean(config.video && config.video.token);
    this.shown = new Map(); // topic -> element, so a refresh keeps the streams open
    this.kind = document.getElementById('image-kind');
    this.kind.addEventListener('change', () => this.restart());
    this.active = false;
  }

  setActive(active) {
    this.active = active;
    if (!active) this.stopAll();
    else this.update(this.topics ?? []);
  }

  update(topics) {
    this.topics = topics;
    const hint = document.getElementById('images-hint');
    const images = topics.filter(([, type]) => IMAGE_TYPES.has(type)).map(([name]) => name);
    if (!this.base) {
      hint.textContent = 'Start the server with --video to see image topics here.';
      return;
    }
    hint.textContent = images.length ? `${images.length} image topic(s) from ${this.base}` : 'No image topics.';
    if (!this.active) return;
    for (const [topic, node] of this.shown) {
      if (!images.includes(topic)) {
        this.stop(node);
        this.shown.delete(topic);
      }
    }
    for (const topic of images) if (!this.shown.has(topic)) this.start(topic);
  }

  start(topic) {
    const kind = this.kind.value;
    const box = el('figure', { class: 'image', dataset: { topic } });
    box.append(el('figcaption', { text: `${topic} (${kind})` }));
    document.getElementById('images').append(box);
    this.shown.set(topic, box);
    this.streamUrl(topic, kind).then((src) => {
      if (box.isConnected) this.play(box, topic, kind, src);
    }, (error) => {
      box.append(el('p', { class: 'error', text: `no video token: ${error.message}` }));
    });
  }

  async streamUrl(topic, kind) {
    const query = { topic, type: kind };
    if (this.needsToken) query.token = (await this.ros.callService('/rwt/video_token')).message;
    return `${this.base}/stream?${new URLSearchParams(query)}`;
  }

  play(box, topic, kind, src) {
    let media;
    if (kind === 'mjpeg') {
      media = el('img', { src, alt: topic });
    } else {
      media = el('video', { src, muted: true, autoplay: true, playsinline: true, 'aria-label': topic });
      media.muted = true; // the property, not only the attribute, decides autoplay
      const button = el('button', { type: 'button', hidden: true, text: '▶ Play' });
      button.addEventListener('click', () => media.play().then(() => (button.hidden = true)));
      media.play().catch(() => (button.hidden = false));
      box.append(button);
    }
    box.prepend(media);
  }

  stop(box) {
    const media = box.querySelector('img, video');
    if (media) media.removeAttribute('src'); // closes the HTTP stream
    if (media && media.load) media.load();
    box.remove();
  }

  stopAll() {
    for (const box of this.shown.values()) this.stop(box);
    this.shown.clear();
  }

  restart() {
    this.stopAll();
    this.update(this.topics ?? []);
  }
}
