// The sign-in page (served as the 401 of any page when the server has a token; this file needs no token):
// the token goes to POST /v1/session once, which answers with the HttpOnly session cookie.
document.getElementById("signin").addEventListener("submit", async (e) => {
  e.preventDefault();
  const message = document.getElementById("message");
  message.textContent = "";
  const answer = await fetch("/v1/session", {
    method: "POST", credentials: "same-origin", headers: { "Content-Type": "application/json" },
    body: JSON.stringify({ token: document.getElementById("token").value.trim() }),
  });
  if (answer.ok) location.reload();
  else if (answer.status === 401) message.textContent = "That is not the server's token.";
  else message.textContent = `The sign-in failed (HTTP ${answer.status}).`;
});
