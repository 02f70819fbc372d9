#include "control/tls.hpp"

#include <arpa/inet.h>
#include <ifaddrs.h>
#include <netinet/in.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <ctime>
#include <filesystem>
#include <functional>

#include <boost/asio/ip/address.hpp>
#include <boost/asio/ssl/context.hpp>
#include <fmt/format.h>
#include <openssl/err.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/rand.h>
#include <openssl/x509.h>
#include <openssl/x509v3.h>

#include "core/error.hpp"
#include "core/io.hpp"

namespace facecap::control {
namespace fs = std::filesystem;
namespace ssl = boost::asio::ssl;

namespace {

constexpr long kValidDays = 825;  // what browsers accepted for a server certificate before 2020's 398

template <class T, void (*Free)(T*)>
struct Deleter {
  void operator()(T* p) const noexcept { Free(p); }
};
using Bio = std::unique_ptr<BIO, Deleter<BIO, BIO_free_all>>;
using Key = std::unique_ptr<EVP_PKEY, Deleter<EVP_PKEY, EVP_PKEY_free>>;
using Certificate = std::unique_ptr<X509, Deleter<X509, X509_free>>;
using Extension = std::unique_ptr<X509_EXTENSION, Deleter<X509_EXTENSION, X509_EXTENSION_free>>;
using Bignum = std::unique_ptr<BIGNUM, Deleter<BIGNUM, BN_free>>;
using Names = std::unique_ptr<GENERAL_NAMES, Deleter<GENERAL_NAMES, GENERAL_NAMES_free>>;

// OpenSSL's last error, for a message (and its queue cleared).
std::string openssl_error() {
  std::string text;
  while (const unsigned long code = ERR_get_error()) {
    std::array<char, 256> line{};
    ERR_error_string_n(code, line.data(), line.size());
    if (!text.empty()) text += "; ";
    text += line.data();
  }
  return text.empty() ? std::string("unknown OpenSSL error") : text;
}

bool is_wildcard(const boost::asio::ip::address& a) { return a.is_unspecified(); }

// Every address of this machine's interfaces that is up, for a box listening on 0.0.0.0.
std::vector<std::string> interface_addresses() {
  std::vector<std::string> out;
  ifaddrs* list = nullptr;
  if (::getifaddrs(&list) != 0) return out;
  for (const ifaddrs* i = list; i; i = i->ifa_next) {
    if (!i->ifa_addr || (i->ifa_addr->sa_family != AF_INET && i->ifa_addr->sa_family != AF_INET6)) continue;
    std::array<char, INET6_ADDRSTRLEN> text{};
    const void* bytes = i->ifa_addr->sa_family == AF_INET
                            ? static_cast<const void*>(&reinterpret_cast<const sockaddr_in*>(i->ifa_addr)->sin_addr)
                            : static_cast<const void*>(&reinterpret_cast<const sockaddr_in6*>(i->ifa_addr)->sin6_addr);
    if (!::inet_ntop(i->ifa_addr->sa_family, bytes, text.data(), text.size())) continue;
    if (i->ifa_addr->sa_family == AF_INET6 && IN6_IS_ADDR_LINKLOCAL(static_cast<const in6_addr*>(bytes))) continue;
    out.emplace_back(text.data());
  }
  ::freeifaddrs(list);
  return out;
}

// subjectAltName entries for `names`: IP literals as IP:, anything else as DNS:, the
// wildcard address as every interface's, and localhost always.
std::vector<std::string> alt_names(const std::vector<std::string>& names) {
  std::vector<std::string> out{"DNS:localhost"};
  auto add = [&](std::string entry) {
    if (std::find(out.begin(), out.end(), entry) == out.end()) out.push_back(std::move(entry));
  };
  for (const std::string& name : names) {
    boost::system::error_code ec;
    const auto address = boost::asio::ip::make_address(name, ec);
    if (ec) {
      add("DNS:" + name);
    } else if (is_wildcard(address)) {
      for (const std::string& a : interface_addresses()) add("IP:" + a);
    } else {
      add("IP:" + address.to_string());
    }
  }
  return out;
}

std::string hex_colons(const unsigned char* bytes, unsigned n) {
  std::string out;
  for (unsigned i = 0; i < n; ++i) out += fmt::format("{}{:02X}", i ? ":" : "", bytes[i]);
  return out;
}

void describe(const X509* cert, TlsIdentity& id) {
  std::array<unsigned char, EVP_MAX_MD_SIZE> md{};
  unsigned n = 0;
  if (X509_digest(cert, EVP_sha256(), md.data(), &n) == 1) id.sha256_fingerprint = hex_colons(md.data(), n);
  // SHA-256 of the DER SubjectPublicKeyInfo, base64: what HPKP and chromium's
  // --ignore-certificate-errors-spki-list pin.
  unsigned char* der = nullptr;
  const int der_size = i2d_X509_PUBKEY(X509_get_X509_PUBKEY(cert), &der);
  if (der_size > 0 && EVP_Digest(der, std::size_t(der_size), md.data(), &n, EVP_sha256(), nullptr) == 1) {
    std::array<unsigned char, 4 * EVP_MAX_MD_SIZE / 3 + 4> b64{};
    EVP_EncodeBlock(b64.data(), md.data(), int(n));
    id.spki_sha256_base64 = reinterpret_cast<const char*>(b64.data());
  }
  OPENSSL_free(der);
  std::tm tm{};
  if (ASN1_TIME_to_tm(X509_get0_notAfter(cert), &tm) == 1) {
    std::array<char, 32> text{};
    std::strftime(text.data(), text.size(), "%Y-%m-%d %H:%M:%S UTC", &tm);
    id.not_after = text.data();
  }
  const Names names(static_cast<GENERAL_NAMES*>(X509_get_ext_d2i(cert, NID_subject_alt_name, nullptr, nullptr)));
  for (int i = 0; names && i < sk_GENERAL_NAME_num(names.get()); ++i) {
    const GENERAL_NAME* name = sk_GENERAL_NAME_value(names.get(), i);
    if (name->type == GEN_DNS) {
      id.names.push_back("DNS:" + std::string(reinterpret_cast<const char*>(ASN1_STRING_get0_data(name->d.dNSName)),
                                              std::size_t(ASN1_STRING_length(name->d.dNSName))));
    } else if (name->type == GEN_IPADD) {
      const int length = ASN1_STRING_length(name->d.iPAddress);
      std::array<char, INET6_ADDRSTRLEN> text{};
      if ((length == 4 || length == 16) &&
          ::inet_ntop(length == 4 ? AF_INET : AF_INET6, ASN1_STRING_get0_data(name->d.iPAddress), text.data(), text.size()))
        id.names.push_back(std::string("IP:") + text.data());
    }
  }
}

void add_extension(X509* cert, int nid, const std::string& value) {
  X509V3_CTX ctx;
  X509V3_set_ctx_nodb(&ctx);
  X509V3_set_ctx(&ctx, cert, cert, nullptr, nullptr, 0);
  const Extension extension(X509V3_EXT_conf_nid(nullptr, &ctx, nid, value.c_str()));
  if (!extension || X509_add_ext(cert, extension.get(), -1) != 1)
    throw Error(fmt::format("TLS: cannot add {} to the certificate: {}", OBJ_nid2sn(nid), openssl_error()));
}

std::string pem(const std::function<int(BIO*)>& write, const std::string& what) {
  const Bio bio(BIO_new(BIO_s_mem()));
  if (!bio || write(bio.get()) != 1) throw Error(fmt::format("TLS: cannot encode the {}: {}", what, openssl_error()));
  char* data = nullptr;
  const long size = BIO_get_mem_data(bio.get(), &data);
  return std::string(data, std::size_t(size));
}

TlsIdentity generate(const TlsFiles& files, const std::vector<std::string>& names) {
  const Key key(EVP_EC_gen("P-256"));
  if (!key) throw Error(fmt::format("TLS: cannot generate a P-256 key: {}", openssl_error()));
  const Certificate cert(X509_new());
  std::array<unsigned char, 16> serial{};
  if (!cert || RAND_bytes(serial.data(), int(serial.size())) != 1)
    throw Error(fmt::format("TLS: cannot make a certificate: {}", openssl_error()));
  serial[0] &= 0x7f;  // a positive serial number
  const Bignum serial_number(BN_bin2bn(serial.data(), int(serial.size()), nullptr));
  std::array<char, 256> host{};
  ::gethostname(host.data(), host.size() - 1);
  X509_NAME* subject = X509_get_subject_name(cert.get());
  const std::string common_name = fmt::format("facecapd on {}", host.data());
  if (X509_set_version(cert.get(), 2) != 1 || !BN_to_ASN1_INTEGER(serial_number.get(), X509_get_serialNumber(cert.get())) ||
      !X509_gmtime_adj(X509_getm_notBefore(cert.get()), -3600) ||
      !X509_gmtime_adj(X509_getm_notAfter(cert.get()), kValidDays * 86400) || X509_set_pubkey(cert.get(), key.get()) != 1 ||
      X509_NAME_add_entry_by_txt(subject, "CN", MBSTRING_UTF8, reinterpret_cast<const unsigned char*>(common_name.c_str()), -1,
                                 -1, 0) != 1 ||
      X509_set_issuer_name(cert.get(), subject) != 1)
    throw Error(fmt::format("TLS: cannot make a certificate: {}", openssl_error()));
  std::string san;
  for (const std::string& name : alt_names(names)) san += (san.empty() ? "" : ",") + name;
  add_extension(cert.get(), NID_basic_constraints, "critical,CA:FALSE");
  add_extension(cert.get(), NID_key_usage, "critical,digitalSignature");
  add_extension(cert.get(), NID_ext_key_usage, "serverAuth");
  add_extension(cert.get(), NID_subject_key_identifier, "hash");
  add_extension(cert.get(), NID_subject_alt_name, san);
  if (X509_sign(cert.get(), key.get(), EVP_sha256()) <= 0)
    throw Error(fmt::format("TLS: cannot sign the certificate: {}", openssl_error()));

  const std::string key_pem = pem([&](BIO* b) { return PEM_write_bio_PrivateKey(b, key.get(), nullptr, nullptr, 0, nullptr, nullptr); }, "key");
  const std::string cert_pem = pem([&](BIO* b) { return PEM_write_bio_X509(b, cert.get()); }, "certificate");
  for (const std::string* file : {&files.key, &files.certificate}) {
    const fs::path parent = fs::path(*file).parent_path();
    std::error_code ec;
    if (!parent.empty() && !fs::exists(parent, ec)) {
      fs::create_directories(parent, ec);
      if (ec) throw file_error(parent.string(), fmt::format("cannot create the TLS directory: {}", ec.message()));
      fs::permissions(parent, fs::perms::owner_all, ec);
    }
  }
  write_file_atomically(files.key, key_pem, 0600);
  write_file_atomically(files.certificate, cert_pem, 0644);
  TlsIdentity id;
  id.generated = true;
  describe(cert.get(), id);
  return id;
}

Certificate read_certificate(const std::string& file) {
  const std::vector<char> bytes = read_file_bytes(file);
  const Bio bio(BIO_new_mem_buf(bytes.data(), int(bytes.size())));
  Certificate cert(bio ? PEM_read_bio_X509(bio.get(), nullptr, nullptr, nullptr) : nullptr);
  if (!cert) throw file_error(file, fmt::format("not a PEM certificate: {}", openssl_error()));
  return cert;
}

void refuse_readable_key(const std::string& file) {
  struct stat info {};
  if (::stat(file.c_str(), &info) == 0 && (info.st_mode & 077) != 0)
    throw file_error(file, fmt::format("holds the TLS private key but group or others may access it (mode {:04o}): chmod 600 it",
                                       info.st_mode & 07777));
}

TlsIdentity load(const TlsFiles& files, const std::vector<std::string>& names) {
  refuse_readable_key(files.key);
  const Certificate cert = read_certificate(files.certificate);
  const std::vector<char> key_bytes = read_file_bytes(files.key);
  const Bio bio(BIO_new_mem_buf(key_bytes.data(), int(key_bytes.size())));
  const Key key(bio ? PEM_read_bio_PrivateKey(bio.get(), nullptr, nullptr, nullptr) : nullptr);
  if (!key) throw file_error(files.key, fmt::format("not a PEM private key (or one with a passphrase): {}", openssl_error()));
  if (X509_check_private_key(cert.get(), key.get()) != 1)
    throw file_error(files.key, fmt::format("is not the key of the certificate {}", files.certificate));
  TlsIdentity id;
  describe(cert.get(), id);
  if (X509_cmp_current_time(X509_get0_notAfter(cert.get())) < 0)
    id.warnings.push_back(fmt::format("the TLS certificate {} expired on {}: browsers refuse it (delete it and {} to have a "
                                      "new one made at the next start)", files.certificate, id.not_after, files.key));
  for (const std::string& name : names) {
    boost::system::error_code ec;
    const auto address = boost::asio::ip::make_address(name, ec);
    if (!ec && is_wildcard(address)) continue;
    const bool covered = ec ? X509_check_host(cert.get(), name.c_str(), name.size(), 0, nullptr) == 1
                            : X509_check_ip_asc(cert.get(), address.to_string().c_str(), 0) == 1;
    if (!covered)
      id.warnings.push_back(fmt::format("the TLS certificate {} does not name {}: browsers reaching the box by it will "
                                        "refuse it (delete it and {} to have a new one made at the next start)",
                                        files.certificate, name, files.key));
  }
  return id;
}

}  // namespace

TlsIdentity ensure_tls_identity(const TlsFiles& files, const std::vector<std::string>& names) {
  std::error_code ec;
  const bool have_certificate = fs::exists(files.certificate, ec), have_key = fs::exists(files.key, ec);
  if (have_certificate != have_key)
    throw file_error(have_certificate ? files.key : files.certificate,
                     fmt::format("does not exist but {} does: give both, or remove both to have a new pair made",
                                 have_certificate ? files.certificate : files.key));
  return have_certificate ? load(files, names) : generate(files, names);
}

std::shared_ptr<ssl::context> make_tls_server_context(const TlsFiles& files) {
  auto context = std::make_shared<ssl::context>(ssl::context::tls_server);
  SSL_CTX_set_min_proto_version(context->native_handle(), TLS1_2_VERSION);
  context->set_options(ssl::context::default_workarounds | ssl::context::no_compression | ssl::context::single_dh_use);
  boost::system::error_code ec;
  context->use_certificate_chain_file(files.certificate, ec);
  if (ec) throw file_error(files.certificate, fmt::format("TLS: cannot use the certificate: {}", ec.message()));
  refuse_readable_key(files.key);
  context->use_private_key_file(files.key, ssl::context::pem, ec);
  if (ec) throw file_error(files.key, fmt::format("TLS: cannot use the private key: {}", ec.message()));
  return context;
}

}  // namespace facecap::control
