// The login page: the token for a session cookie (HttpOnly, so no script ever reads it),
// then back to the page that sent us here.
import { call, show } from './api.js';

const $ = (id) => document.getElementById(id);

// Only a page of this dashboard: never an address given in the query.
function nextPage() {
  const next = new URLSearchParams(location.search).get('next') ?? './';
  return /^\.\/[\w.\-]*(\?[\w=&.%\-]*)?$/.test(next) ? next : './';
}

$('login-form').addEventListener('submit', async (event) => {
  event.preventDefault();
  $('login').disabled = true;
  try {
    const answer = await call('/login', { token: $('token').value });
    document.body.dataset.role = answer.role;
    location.replace(nextPage());
  } catch (e) {
    show($('login-message'), e);
    $('login').disabled = false;
  }
});
