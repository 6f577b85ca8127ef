// Service calls and action goals from forms generated from their types.
import { typedefForm } from './forms.js';
import { el, jsonTree, showError } from './ui.js';

export class ServiceView {
  constructor(ros) {
    this.ros = ros;
    this.form = null;
    document.getElementById('service-form').addEventListener('submit', (event) => {
      event.preventDefault();
      this.call();
    });
  }

  async show(service) {
    this.service = service;
    document.getElementById('service-hint').hidden = true;
    document.getElementById('service-form').hidden = false;
    document.getElementById('service-name').textContent = service;
    document.getElementById('service-result').replaceChildren();
    const fields = document.getElementById('service-fields');
    fields.replaceChildren(el('p', { class: 'muted', text: 'loading the type…' }));
    try {
      const { type } = await this.ros.callService('/rosapi/service_type', { service });
      document.getElementById('service-type').textContent = type;
      const details = await this.ros.callService('/rosapi/service_request_details', { type });
      if (this.service !== service) return;
      this.form = typedefForm(details.typedefs, 'req');
      fields.replaceChildren(this.form.node);
    } catch (error) {
      showError(fields, error);
    }
  }

  async call() {
    const out = document.getElementById('service-result');
    try {
      const args = this.form.read();
      out.replaceChildren(el('p', { class: 'muted', text: 'calling…' }));
      const values = await this.ros.callService(this.service, args);
      out.replaceChildren(el('h3', { text: 'Response' }), jsonTree(values));
    } catch (error) {
      showError(out, error);
    }
  }
}

export class ActionView {
  constructor(ros) {
    this.ros = ros;
    this.form = null;
    this.goal = null;
    document.getElementById('action-form').addEventListener('submit', (event) => {
      event.preventDefault();
      this.send();
    });
    document.getElementById('action-cancel').addEventListener('click', () => {
      if (this.goal) this.goal.cancel();
    });
  }

  async show(action) {
    this.action = action;
    document.getElementById('action-hint').hidden = true;
    document.getElementById('action-form').hidden = false;
    document.getElementById('action-name').textContent = action;
    const fields = document.getElementById('action-fields');
    fields.replaceChildren(el('p', { class: 'muted', text: 'loading the type…' }));
    try {
      const { type } = await this.ros.callService('/rosapi/action_type', { action });
      this.type = type;
      document.getElementById('action-type').textContent = type;
      const details = await this.ros.callService('/rosapi/action_goal_details', { type });
      if (this.action !== action) return;
      this.form = typedefForm(details.typedefs, 'goal');
      fields.replaceChildren(this.form.node);
    } catch (error) {
      showError(fields, error);
    }
  }

  async send() {
    const feedback = document.getElementById('action-feedback');
    const result = document.getElementById('action-result');
    const cancel = document.getElementById('action-cancel');
    try {
      const args = this.form.read();
      feedback.replaceChildren();
      result.replaceChildren(el('p', { class: 'muted', text: 'running…' }));
      this.goal = this.ros.sendActionGoal(this.action, this.type, args, (values) => {
        feedback.prepend(el('div', { class: 'message' }, jsonTree(values)));
        while (feedback.children.length > 20) feedback.lastChild.remove();
      });
      cancel.disabled = false;
      const done = await this.goal.done;
      result.replaceChildren(el('p', { text: `status ${done.status}${done.result === false ? ' (failed)' : ''}` }),
        jsonTree(done.values));
    } catch (error) {
      showError(result, error);
    } finally {
      cancel.disabled = true;
      this.goal = null;
    }
  }
}
