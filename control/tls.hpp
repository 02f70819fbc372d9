#pragma once
// The control API's TLS identity (docs/control-api.md#tls): a certificate and its private
// key in PEM files, generated on first start when neither exists (a self-signed ECDSA
// P-256 certificate naming the box's addresses and names), loaded and checked otherwise.
// Not real-time code; runs once at facecapd's start.
#include <memory>
#include <string>
#include <vector>

namespace boost::asio::ssl {
class context;
}

namespace facecap::control {

struct TlsFiles {
  std::string certificate;  // PEM certificate (chain), e.g. tls/facecapd.crt
  std::string key;          // PEM private key, refused when group or others may read it
};

struct TlsIdentity {
  bool generated = false;          // made now, since neither file existed
  std::string sha256_fingerprint;  // of the certificate, "AB:CD:...", as browsers show it
  std::string spki_sha256_base64;  // of its public key (certificate pinning, chromium's SPKI list)
  std::string not_after;           // "2028-11-28 10:00:00 UTC"
  std::vector<std::string> names;  // its subjectAltName entries ("IP:127.0.0.1", "DNS:localhost")
  std::vector<std::string> warnings;  // an expired certificate, a name it does not cover
};

// The certificate and key of `files`: loaded when both exist, generated (directories
// made, the key written 0600) when neither does. A new certificate names `names` (IP
// addresses and host names; an IP that is 0.0.0.0 or :: stands for every address of this
// machine's interfaces) and is valid for 825 days. A loaded one is checked against its
// key, and warnings say when it has expired or does not name one of `names`. Throws Error
// naming the file on anything else: one file without the other, a key others may read,
// a file OpenSSL cannot read.
TlsIdentity ensure_tls_identity(const TlsFiles& files, const std::vector<std::string>& names);

// A TLS server context (TLS 1.2 and later) serving `files`. Throws Error naming the file.
std::shared_ptr<boost::asio::ssl::context> make_tls_server_context(const TlsFiles& files);

}  // namespace facecap::control
