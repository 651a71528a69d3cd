// yscene serve: the page. Polls /api/state, shows the current frame, and
// turns the controls into POST edits (the API: yocto_serve.h and the
// server's contract). Every request carries the page's token.
'use strict';

(function () {
  const token = new URLSearchParams(location.search).get('token') || '';
  const $ = (id) => document.getElementById(id);

  let state = null;      // the last /api/state
  let signature = '';    // what the controls were built from

  // ---------------------------------------------------------------------------
  // STATUS LINE
  // ---------------------------------------------------------------------------
  let statusKind = '';  // '', 'edit', 'connection', 'info'
  function showStatus(message, kind, isError) {
    const status = $('status');
    status.textContent = message;
    status.classList.toggle('error', !!isError);
    statusKind = message ? kind : '';
  }
  function clearStatus(kind) {
    if (statusKind === kind) showStatus('', '', false);
  }
  function describeError(response) {
    const body = response.body || {};
    let message = body.error || 'HTTP ' + response.status;
    if (body.field && message.indexOf(body.field) < 0) message += ' (' + body.field + ')';
    return message;
  }

  // ---------------------------------------------------------------------------
  // REQUESTS
  // ---------------------------------------------------------------------------
  async function api(path, body) {
    const options = { headers: { 'X-Token': token }, cache: 'no-store' };
    if (body !== undefined) {
      options.method = 'POST';
      options.headers['Content-Type'] = 'application/json';
      options.body = JSON.stringify(body);
    }
    const response = await fetch(path, options);
    let json = null;
    try {
      json = await response.json();
    } catch (e) {
      json = null;
    }
    return { ok: response.ok, status: response.status, body: json };
  }

  // Edits go one at a time: each control (or camera gesture) has a key whose
  // latest body waits in `queue` while another request is in flight, so a
  // slider sends at most one request at a time and always its last value.
  const queue = new Map();     // key -> {path, body}
  const awaited = new Map();   // key -> the generation that will show it
  let sending = null;          // the key in flight

  function post(key, path, body) {
    queue.set(key, { path: path, body: body });
    pump();
  }
  // Camera gestures accumulate while a request is in flight.
  function postMerged(key, path, delta, merge) {
    const old = queue.get(key);
    queue.set(key, { path: path, body: old ? merge(old.body, delta) : delta });
    pump();
  }
  async function pump() {
    if (sending !== null || queue.size === 0) return;
    const [key, item] = queue.entries().next().value;
    queue.delete(key);
    sending = key;
    try {
      const response = await api(item.path, item.body);
      if (response.ok && response.body && typeof response.body.generation === 'number') {
        awaited.set(key, response.body.generation);
        clearStatus('edit');
      } else {
        showStatus(describeError(response), 'edit', true);
      }
    } catch (e) {
      showStatus('request failed: ' + e.message, 'connection', true);
    } finally {
      sending = null;
      pump();
    }
  }
  // Whether a control's value is ours rather than the state's: queued, in
  // flight, or sent but not yet in the state polled.
  function busy(key) {
    if (queue.has(key) || sending === key) return true;
    if (!awaited.has(key)) return false;
    if (state && state.generation >= awaited.get(key)) {
      awaited.delete(key);
      return false;
    }
    return true;
  }

  // ---------------------------------------------------------------------------
  // FORMATTING
  // ---------------------------------------------------------------------------
  function fmt(value) {
    if (!isFinite(value)) return String(value);
    return String(Number(Number(value).toPrecision(4)));
  }
  function fmtCount(value) {
    const units = [[1e9, 'G'], [1e6, 'M'], [1e3, 'k']];
    for (const [scale, unit] of units)
      if (Math.abs(value) >= scale) return (value / scale).toFixed(2) + ' ' + unit;
    return value.toFixed(0);
  }
  function toHex(rgb) {
    return '#' + rgb.map((c) => {
      const v = Math.round(Math.min(Math.max(c, 0), 1) * 255);
      return (v < 16 ? '0' : '') + v.toString(16);
    }).join('');
  }
  function fromHex(hex) {
    return [1, 3, 5].map((i) => parseInt(hex.substr(i, 2), 16) / 255);
  }
  function rangeText(p) {
    const lo = p.min === null || p.min === undefined ? null : p.min;
    const hi = p.max === null || p.max === undefined ? null : p.max;
    if (lo !== null && hi !== null)
      return 'in ' + (p.min_open ? '(' : '[') + fmt(lo) + ', ' + fmt(hi) + (p.max_open ? ')' : ']');
    if (lo !== null) return (p.min_open ? '> ' : '>= ') + fmt(lo);
    if (hi !== null) return (p.max_open ? '< ' : '<= ') + fmt(hi);
    return 'any value';
  }

  // ---------------------------------------------------------------------------
  // CONTROLS
  // ---------------------------------------------------------------------------
  function element(tag, attributes, parent) {
    const node = document.createElement(tag);
    for (const name in attributes) {
      if (name === 'text') node.textContent = attributes[name];
      else node.setAttribute(name, attributes[name]);
    }
    if (parent) parent.appendChild(node);
    return node;
  }

  // A label, a range slider and a number input: `send(value)` on input of
  // the slider and on change of the typed number. The slider's top for
  // unbounded values is `top`, raised when a value goes past it.
  function numberControl(parent, options) {
    const row = element('label', { class: 'row' }, parent);
    const label = element('span', { text: options.label, title: options.title }, row);
    row.title = options.title;
    let lo = options.min === null || options.min === undefined ? 0 : options.min;
    let hi = options.max === null || options.max === undefined ? options.top : options.max;
    const epsilon = (hi - lo) * 1e-4;
    const slider = element('input', { type: 'range', id: options.id, step: 'any' }, row);
    slider.min = options.minOpen ? lo + epsilon : lo;
    slider.max = options.maxOpen ? hi - epsilon : hi;
    const number = element('input', { type: 'number', id: options.id + '-value', step: 'any' }, row);
    if (options.min !== null && options.min !== undefined) number.min = options.min;
    if (options.max !== null && options.max !== undefined) number.max = options.max;
    const unbounded = options.max === null || options.max === undefined;
    function raise(value) {
      if (unbounded && value > Number(slider.max)) slider.max = 2 * value;
    }
    function set(value, isSet) {
      raise(value);
      slider.value = value;
      if (document.activeElement !== number) number.value = fmt(value);
      row.classList.toggle('unset', isSet === false);
      label.title = options.title + (isSet === false ? ' (not set)' : '');
    }
    slider.addEventListener('input', () => {
      const value = Number(slider.value);
      number.value = fmt(value);
      options.send(value);
    });
    slider.addEventListener('change', () => options.send(Number(slider.value)));
    number.addEventListener('change', () => {
      const value = Number(number.value);
      if (number.value === '' || !isFinite(value)) return;
      raise(value);
      slider.value = value;
      options.send(value);
    });
    return {
      update: (value, isSet) => {
        if (!options.isBusy() && document.activeElement !== number) set(value, isSet);
      },
      init: (value, isSet) => set(value, isSet),
    };
  }

  // An r g b colour in [0, 1] as a colour picker (the hex digits are the
  // values, no transfer curve).
  function colorControl(parent, options) {
    const row = element('label', { class: 'row' }, parent);
    const label = element('span', { text: options.label, title: options.title }, row);
    row.title = options.title;
    const input = element('input', { type: 'color', id: options.id, class: 'wide' }, row);
    const text = element('output', {}, row);
    function set(value, isSet) {
      input.value = toHex(value);
      text.textContent = value.map((c) => c.toFixed(2)).join(' ');
      row.classList.toggle('unset', isSet === false);
      label.title = options.title + (isSet === false ? ' (not set)' : '');
    }
    input.addEventListener('input', () => {
      const value = fromHex(input.value);
      text.textContent = value.map((c) => c.toFixed(2)).join(' ');
      options.send(value);
    });
    return {
      update: (value, isSet) => { if (!options.isBusy()) set(value, isSet); },
      init: set,
    };
  }

  // Three numbers (unbounded r g b, like absorptions, or a direction).
  function tripleControl(parent, options) {
    const row = element('div', { class: 'row rgb3' }, parent);
    const label = element('span', { text: options.label, title: options.title }, row);
    row.title = options.title;
    const triple = element('div', { class: 'triple', id: options.id }, row);
    const inputs = [0, 1, 2].map((c) => {
      const input = element('input', { type: 'number', id: options.id + '-' + c, step: 'any' }, triple);
      if (options.min !== null && options.min !== undefined) input.min = options.min;
      input.addEventListener('change', () => {
        const value = inputs.map((i) => Number(i.value));
        if (inputs.some((i) => i.value === '') || !value.every(isFinite)) return;
        options.send(value);
      });
      return input;
    });
    function set(value, isSet) {
      inputs.forEach((input, c) => { if (document.activeElement !== input) input.value = fmt(value[c]); });
      row.classList.toggle('unset', isSet === false);
      label.title = options.title + (isSet === false ? ' (not set)' : '');
    }
    return {
      update: (value, isSet) => {
        if (!options.isBusy() && !inputs.includes(document.activeElement)) set(value, isSet);
      },
      init: set,
    };
  }

  let controls = [];  // {update(state)}

  function stateSignature(s) {
    return JSON.stringify([
      s.cameras, s.layers,
      s.materials.map((m) => [m.index, m.name, m.parameters.map((p) => [p.name, p.kind, p.min, p.max])]),
      s.environments.map((e) => [e.index, e.name]),
      s.lights.map((l) => l.index),
    ]);
  }

  function fillSelect(select, names, keep) {
    const old = select.value;
    select.textContent = '';
    names.forEach((name, i) => element('option', { value: keep ? name : String(i), text: name }, select));
    if (keep && names.indexOf(old) >= 0) select.value = old;
  }

  function buildControls(s) {
    controls = [];
    fillSelect($('layer'), s.layers, true);
    fillSelect($('camera'), s.cameras, false);
    $('camera').value = String(s.camera);

    const materials = $('materials');
    materials.textContent = '';
    s.materials.forEach((material, m) => {
      const fieldset = element('fieldset', { id: 'material-' + material.index }, materials);
      element('legend', { text: 'hair: ' + material.name }, fieldset);
      let group = '';
      material.parameters.forEach((p, k) => {
        if (p.group !== group) {
          group = p.group;
          element('h2', { text: group }, fieldset);
        }
        const id = 'm' + material.index + '-' + p.name;
        const key = id;
        const title = p.name + (p.unit ? ' (' + p.unit + ')' : '') + ': ' + p.doc + '; ' + rangeText(p);
        const options = {
          id: id,
          label: p.name.replace(/_/g, ' ') + (p.unit ? ' (' + p.unit + ')' : ''),
          title: title,
          min: p.min,
          max: p.max,
          minOpen: p.min_open,
          maxOpen: p.max_open,
          top: /melanin/.test(p.name) ? 8 : Math.max(2 * (Number(p.value) || 0), 8),
          isBusy: () => busy(key),
          send: (value) => post(key, '/api/material',
              { material: material.index, parameter: p.name, value: value }),
        };
        let control;
        if (p.kind === 'number') control = numberControl(fieldset, options);
        else if (p.max === null || p.max === undefined) control = tripleControl(fieldset, options);
        else control = colorControl(fieldset, options);
        control.init(p.value, p.set);
        controls.push((state) => {
          const param = state.materials[m].parameters[k];
          control.update(param.value, param.set);
        });
      });
    });

    const lighting = $('lighting');
    lighting.textContent = '';
    if (s.environments.length || s.lights.length) {
      const fieldset = element('fieldset', {}, lighting);
      element('legend', { text: 'lights' }, fieldset);
      s.environments.forEach((environment, e) => {
        const key = 'e' + environment.index;
        const control = numberControl(fieldset, {
          id: 'e' + environment.index + '-strength',
          label: 'env ' + environment.name,
          title: 'environment ' + environment.name + ': strength, times the loaded emission; in [0, 1000]',
          min: 0, max: null, top: Math.max(4, 2 * environment.strength),
          isBusy: () => busy(key),
          send: (value) => post(key, '/api/environment', { environment: environment.index, strength: value }),
        });
        control.init(environment.strength);
        controls.push((state) => control.update(state.environments[e].strength));
      });
      s.lights.forEach((light, l) => {
        const key = 'l' + light.index;
        const control = numberControl(fieldset, {
          id: 'l' + light.index + '-strength',
          label: 'light ' + light.index,
          title: 'distant light ' + light.index + ': strength, times the loaded emission; in [0, 1000]',
          min: 0, max: null, top: Math.max(4, 2 * light.strength),
          isBusy: () => busy(key),
          send: (value) => post(key, '/api/light', { light: light.index, strength: value }),
        });
        control.init(light.strength);
        controls.push((state) => control.update(state.lights[l].strength));
        const directionKey = 'l' + light.index + '-direction';
        const direction = tripleControl(fieldset, {
          id: 'l' + light.index + '-direction',
          label: 'direction',
          title: 'distant light ' + light.index + ': direction x y z (normalized by the server)',
          min: null,
          isBusy: () => busy(directionKey),
          send: (value) => post(directionKey, '/api/light', { light: light.index, direction: value }),
        });
        direction.init(light.direction);
        controls.push((state) => direction.update(state.lights[l].direction));
      });
    }
  }

  // ---------------------------------------------------------------------------
  // STATE
  // ---------------------------------------------------------------------------
  function applyState(s) {
    state = s;
    const newSignature = stateSignature(s);
    if (newSignature !== signature) {
      signature = newSignature;
      buildControls(s);
      fit();
    } else {
      controls.forEach((update) => update(s));
      if (!busy('camera') && !busy('camera-reset') && document.activeElement !== $('camera'))
        $('camera').value = String(s.camera);
    }
    $('scene').textContent = s.scene;
    $('scene').title = s.scene;
    $('samples').textContent = String(s.samples);
    $('target').textContent = String(s.target_samples);
    $('rate').textContent = fmtCount(s.samples_per_second);
    $('time').textContent = s.seconds.toFixed(1);
    $('preview').hidden = !s.preview;
    $('output-dir').textContent = 'into ' + s.output_dir;
    $('output-dir').title = s.output_dir;
    refreshFrame();
  }

  // A long poll: the server answers when a frame after the one we have is
  // published (or after a quarter of a second), so a new frame shows when
  // it comes; after an error, a pause before the next try.
  async function poll() {
    let pause = 0;
    try {
      const response = await api('/api/state' + (state ? '?after=' + state.frame : ''));
      if (response.ok && response.body) {
        clearStatus('connection');
        applyState(response.body);
      } else {
        showStatus(describeError(response), 'connection', true);
        pause = 500;
      }
    } catch (e) {
      showStatus('server not reachable (' + e.message + ')', 'connection', true);
      pause = 500;
    }
    setTimeout(poll, pause);
  }

  // ---------------------------------------------------------------------------
  // FRAME
  // ---------------------------------------------------------------------------
  const frame = () => $('frame');
  let loading = false;
  let shownUrl = '';
  let requestedUrl = '';

  function frameUrl() {
    const exposure = Number($('exposure').value);
    return '/api/frame.png?token=' + encodeURIComponent(token) +
        '&layer=' + encodeURIComponent($('layer').value || 'color') +
        '&exposure=' + encodeURIComponent(String(exposure)) +
        '&view=' + encodeURIComponent($('view').value) +
        '&n=' + state.frame;
  }
  // One image load at a time: the next starts when the last has finished.
  function refreshFrame() {
    if (!state || !state.frame || loading) return;
    const url = frameUrl();
    if (url === shownUrl) return;
    loading = true;
    requestedUrl = url;
    frame().dataset.requested = String(state.frame);
    frame().src = url;
  }
  function frameDone(ok) {
    loading = false;
    shownUrl = requestedUrl;
    if (ok) {
      frame().dataset.frame = frame().dataset.requested;
      fit();
    } else {
      showStatus('could not load the frame', 'frame', true);
    }
    refreshFrame();
  }

  // The image as large as the viewport allows, its aspect kept.
  function fit() {
    const img = frame();
    // The render's size, not the frame's: previews are smaller.
    const width = (state && state.width) || img.naturalWidth || 0;
    const height = (state && state.height) || img.naturalHeight || 0;
    if (!width || !height) return;
    const viewport = $('viewport');
    const scale = Math.min(viewport.clientWidth / width, viewport.clientHeight / height);
    img.style.width = Math.max(1, Math.floor(width * scale)) + 'px';
    img.style.height = Math.max(1, Math.floor(height * scale)) + 'px';
  }

  // ---------------------------------------------------------------------------
  // CAMERA GESTURES
  // ---------------------------------------------------------------------------
  const clamp = (x, lo, hi) => Math.min(Math.max(x, lo), hi);
  const addPairs = (key) => (a, b) => {
    const out = {};
    out[key] = [clamp(a[key][0] + b[key][0], -10, 10), clamp(a[key][1] + b[key][1], -10, 10)];
    return out;
  };
  const multiplyZoom = (a, b) => ({ zoom: clamp(a.zoom * b.zoom, 0.01, 100) });

  function setupGestures() {
    const img = frame();
    let mode = null;
    let last = null;
    img.addEventListener('contextmenu', (e) => e.preventDefault());
    img.addEventListener('dragstart', (e) => e.preventDefault());
    img.addEventListener('pointerdown', (e) => {
      if (e.button === 0 && !e.shiftKey) mode = 'orbit';
      else if (e.button === 2 || (e.button === 0 && e.shiftKey)) mode = 'pan';
      else return;
      last = { x: e.clientX, y: e.clientY };
      img.setPointerCapture(e.pointerId);
      e.preventDefault();
    });
    img.addEventListener('pointermove', (e) => {
      if (!mode) return;
      const dx = e.clientX - last.x;
      const dy = e.clientY - last.y;
      if (!dx && !dy) return;
      last = { x: e.clientX, y: e.clientY };
      const height = img.getBoundingClientRect().height || 1;
      if (mode === 'orbit') {
        // Dragging across the image's height turns half a turn.
        const delta = { orbit: [dx / height * Math.PI, dy / height * Math.PI] };
        postMerged('camera-orbit', '/api/camera', delta, addPairs('orbit'));
      } else {
        // The scene follows the pointer (fractions of the view's height).
        const delta = { pan: [dx / height, dy / height] };
        postMerged('camera-pan', '/api/camera', delta, addPairs('pan'));
      }
    });
    const end = (e) => {
      mode = null;
      if (img.hasPointerCapture(e.pointerId)) img.releasePointerCapture(e.pointerId);
    };
    img.addEventListener('pointerup', end);
    img.addEventListener('pointercancel', end);
    $('viewport').addEventListener('wheel', (e) => {
      e.preventDefault();
      const pixels = e.deltaY * (e.deltaMode === 1 ? 16 : e.deltaMode === 2 ? 400 : 1);
      const delta = { zoom: clamp(Math.exp(pixels * 0.0015), 0.01, 100) };
      postMerged('camera-zoom', '/api/camera', delta, multiplyZoom);
    }, { passive: false });
  }

  function dropCameraGestures() {
    queue.delete('camera-orbit');
    queue.delete('camera-pan');
    queue.delete('camera-zoom');
  }

  // ---------------------------------------------------------------------------
  // SAVE
  // ---------------------------------------------------------------------------
  async function save() {
    const button = $('save');
    button.disabled = true;
    $('saved').textContent = 'saving (between passes)...';
    try {
      const response = await api('/api/save', { exposure: Number($('exposure').value) });
      if (response.ok && response.body) {
        const b = response.body;
        $('saved').textContent = [b.image, b.png, b.scene].filter((x) => x).join('\n') +
            '\n' + b.samples + ' spp';
        clearStatus('edit');
      } else {
        $('saved').textContent = '';
        showStatus('save: ' + describeError(response), 'edit', true);
      }
    } catch (e) {
      $('saved').textContent = '';
      showStatus('save failed: ' + e.message, 'connection', true);
    } finally {
      button.disabled = false;
    }
  }

  // ---------------------------------------------------------------------------
  // START
  // ---------------------------------------------------------------------------
  function init() {
    const img = frame();
    img.addEventListener('load', () => frameDone(true));
    img.addEventListener('error', () => frameDone(false));
    $('exposure').addEventListener('input', () => {
      $('exposure-value').textContent = Number($('exposure').value).toFixed(1);
      refreshFrame();
    });
    $('view').addEventListener('change', refreshFrame);
    $('layer').addEventListener('change', refreshFrame);
    $('camera').addEventListener('change', () => {
      dropCameraGestures();
      post('camera', '/api/camera', { camera: Number($('camera').value) });
    });
    $('reset').addEventListener('click', () => {
      dropCameraGestures();
      post('camera-reset', '/api/camera', { reset: true });
    });
    $('save').addEventListener('click', save);
    window.addEventListener('resize', fit);
    setupGestures();
    if (!token) showStatus('no token in the URL: open the URL the server printed', 'connection', true);
    poll();
  }

  if (document.readyState === 'loading') document.addEventListener('DOMContentLoaded', init);
  else init();
})();
