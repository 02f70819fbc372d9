// The control API from the page (docs/control-api.md): JSON in and out, every refusal an
// Error carrying facecapd's own message, and one place that shows it on the page.

export class ApiError extends Error {
  constructor(status, message) {
    super(message);
    this.status = status;
  }
}

// GET (no body) or POST (body) a route; resolves to the JSON answer, rejects with ApiError.
export async function call(path, body) {
  let response;
  try {
    response = await fetch(path, body === undefined ? {} : {
      method: 'POST',
      headers: { 'Content-Type': 'application/json' },
      body: JSON.stringify(body),
    });
  } catch (e) {
    throw new ApiError(0, `facecapd does not answer (${e.message})`);
  }
  let answer = null;
  try {
    answer = await response.json();
  } catch {
    throw new ApiError(response.status, `${path}: HTTP ${response.status} without a JSON answer`);
  }
  if (!response.ok) throw new ApiError(response.status, `${answer.error ?? 'refused'} (HTTP ${response.status})`);
  return answer;
}

// Shows a control's outcome in its message element: an error in red, else a note.
export function show(element, error, note = '') {
  element.classList.toggle('error', Boolean(error));
  element.textContent = error ? error.message : note;
}

// Runs an action behind a button: disabled while it runs, its error shown in `message`.
export async function act(button, message, action) {
  button.disabled = true;
  show(message, null, 'working...');
  try {
    const note = await action();
    show(message, null, note ?? '');
  } catch (e) {
    show(message, e);
  } finally {
    button.disabled = false;
  }
}

export function streamUrl(query) {
  const scheme = location.protocol === 'https:' ? 'wss:' : 'ws:';
  return `${scheme}//${location.host}/stream?${query}`;
}

// Text for a number, or '-' when there is none.
export function fmt(value, digits = 1) {
  return typeof value === 'number' && Number.isFinite(value) ? value.toFixed(digits) : '-';
}

export function formatSeconds(seconds) {
  const s = Math.max(0, Math.floor(seconds));
  return `${String(Math.floor(s / 60)).padStart(2, '0')}:${String(s % 60).padStart(2, '0')}`;
}
