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
  if (response.status === 401 && path !== '/login') toLogin();
  if (!response.ok) throw new ApiError(response.status, `${answer.error ?? 'refused'} (HTTP ${response.status})`);
  return answer;
}

// The login page, coming back here after it.
export function toLogin() {
  const here = `./${location.pathname.split('/').pop()}${location.search}`;
  location.replace(`./login.html?next=${encodeURIComponent(here)}`);
}

// A viewer's page: its command controls stay disabled.
export const readOnly = () => document.body.dataset.role === 'viewer';

// Who this page is (GET /session; a 401 goes to the login page): shows the role and a
// Log out button in the header, and marks the page read-only for a viewer.
export async function startSession() {
  const session = await call('/session');
  document.body.dataset.role = session.role;
  const header = document.querySelector('header');
  const who = document.createElement('span');
  who.id = 'session';
  who.className = 'muted';
  who.textContent = session.role === 'viewer' ? 'viewer (read-only)' : '';
  header.append(who);
  if (session.login) {
    const logout = document.createElement('button');
    logout.id = 'logout';
    logout.textContent = 'Log out';
    logout.addEventListener('click', async () => {
      await call('/logout', {}).catch(() => {});
      toLogin();
    });
    header.append(logout);
  }
  if (session.role === 'viewer')
    for (const control of document.querySelectorAll('[data-command] :is(button, input, select)')) control.disabled = true;
  return session;
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
