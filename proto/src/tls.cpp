// The rig's TLS identity and the known-rigs file (veneer/proto/tls.hpp).
#include "veneer/proto/tls.hpp"

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <cctype>
#include <fstream>
#include <memory>
#include <sstream>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <openssl/bn.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/sha.h>
#include <openssl/x509.h>

namespace veneer::tls {

namespace fs = std::filesystem;

namespace {

struct FreeBio { void operator()(BIO* b) const { BIO_free(b); } };
struct FreeKey { void operator()(EVP_PKEY* k) const { EVP_PKEY_free(k); } };
struct FreeX509 { void operator()(X509* x) const { X509_free(x); } };
struct FreeBn { void operator()(BIGNUM* b) const { BN_free(b); } };
using Bio = std::unique_ptr<BIO, FreeBio>;
using Key = std::unique_ptr<EVP_PKEY, FreeKey>;
using Cert = std::unique_ptr<X509, FreeX509>;

Expected<std::string> read_file(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return make_error(file.string() + ": cannot read");
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

std::string fingerprint_of(X509* cert) {
  int n = i2d_X509(cert, nullptr);
  if (n <= 0) return "";
  std::string der(static_cast<size_t>(n), '\0');
  auto* p = reinterpret_cast<unsigned char*>(der.data());
  i2d_X509(cert, &p);
  return fingerprint_of_der(reinterpret_cast<const unsigned char*>(der.data()), der.size());
}

Expected<Cert> load_cert(const fs::path& file) {
  auto pem = read_file(file);
  if (!pem) return pem.error();
  Bio bio(BIO_new_mem_buf(pem->data(), static_cast<int>(pem->size())));
  Cert cert(PEM_read_bio_X509(bio.get(), nullptr, nullptr, nullptr));
  if (!cert) return make_error(file.string() + ": not a PEM certificate");
  return cert;
}

Expected<Key> load_key(const fs::path& file) {
  auto pem = read_file(file);
  if (!pem) return pem.error();
  Bio bio(BIO_new_mem_buf(pem->data(), static_cast<int>(pem->size())));
  Key key(PEM_read_bio_PrivateKey(bio.get(), nullptr, nullptr, nullptr));
  if (!key) return make_error(file.string() + ": not a PEM private key");
  return key;
}

std::string bio_text(BIO* bio) {
  char* data = nullptr;
  long n = BIO_get_mem_data(bio, &data);
  return n > 0 ? std::string(data, static_cast<size_t>(n)) : std::string();
}

Expected<Cert> make_certificate(EVP_PKEY* key, const std::string& common_name) {
  Cert cert(X509_new());
  if (!cert) return make_error("cannot make a certificate (out of memory)");
  X509_set_version(cert.get(), 2);  // v3
  std::unique_ptr<BIGNUM, FreeBn> serial(BN_new());
  BN_rand(serial.get(), 127, BN_RAND_TOP_ANY, BN_RAND_BOTTOM_ANY);  // positive, at most 16 bytes
  BN_to_ASN1_INTEGER(serial.get(), X509_get_serialNumber(cert.get()));
  X509_gmtime_adj(X509_getm_notBefore(cert.get()), -24 * 3600);
  ASN1_TIME_set_string(X509_getm_notAfter(cert.get()), "99991231235959Z");
  X509_NAME* name = X509_get_subject_name(cert.get());
  std::string cn = common_name.empty() ? "veneer-rig" : common_name.substr(0, 64);
  X509_NAME_add_entry_by_txt(name, "CN", MBSTRING_UTF8, reinterpret_cast<const unsigned char*>(cn.c_str()), -1, -1, 0);
  X509_set_issuer_name(cert.get(), name);
  X509_set_pubkey(cert.get(), key);
  if (X509_sign(cert.get(), key, EVP_sha256()) <= 0) return make_error("cannot sign the rig's certificate");
  return cert;
}

}  // namespace

std::string fingerprint_of_der(const unsigned char* der, size_t size) {
  unsigned char md[SHA256_DIGEST_LENGTH];
  SHA256(der, size, md);
  static const char* hex = "0123456789ABCDEF";
  std::string out;
  for (size_t i = 0; i < sizeof md; ++i) {
    if (i) out += ':';
    out += hex[md[i] >> 4];
    out += hex[md[i] & 15];
  }
  return out;
}

Expected<std::string> parse_fingerprint(const std::string& text) {
  std::string digits;
  for (char c : text) {
    if (c == ':' || c == ' ' || c == '\t') continue;
    if (!std::isxdigit(static_cast<unsigned char>(c))) {
      std::string what = "fingerprint '";
      what.append(text, 0, 120);
      what += "': '";
      what.push_back(c);
      what += "' is not a hex digit (expected 64 hex digits, pairs may be joined by ':')";
      return make_error(what);
    }
    digits += static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  }
  if (digits.size() != 64) {
    return make_error("fingerprint '" + text.substr(0, 120) + "': " + std::to_string(digits.size()) +
                      " hex digits, expected 64 (SHA-256)");
  }
  std::string out;
  out.reserve(95);
  for (size_t i = 0; i < 64; ++i) {
    if (i > 0 && i % 2 == 0) out.push_back(':');
    out.push_back(digits[i]);
  }
  return out;
}

Status write_file_atomically(const fs::path& file, const std::string& bytes, unsigned mode) {
  std::error_code ec;
  const fs::path dir = file.parent_path().empty() ? fs::path(".") : file.parent_path();
  fs::create_directories(dir, ec);
  std::string name = file.filename().string();
  name.insert(name.begin(), '.');
  name.append(".tmp-XXXXXX");
  std::string temp = (dir / name).string();
  int fd = ::mkstemp(temp.data());
  if (fd < 0) return make_error(file.string() + ": cannot create a temporary file beside it: " + std::strerror(errno));
  bool ok = ::fchmod(fd, static_cast<mode_t>(mode)) == 0;
  size_t done = 0;
  while (ok && done < bytes.size()) {
    ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    ok = n > 0;
    if (ok) done += static_cast<size_t>(n);
  }
  ok = ok && ::fsync(fd) == 0;
  const int err = errno;
  ok = ::close(fd) == 0 && ok;
  if (!ok || ::rename(temp.c_str(), file.c_str()) != 0) {
    const int why = ok ? errno : err;
    ::unlink(temp.c_str());
    return make_error(file.string() + ": cannot write: " + std::strerror(why));
  }
  int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd >= 0) {
    ::fsync(dfd);
    ::close(dfd);
  }
  return {};
}

Expected<Identity> ensure_identity(const fs::path& key_file, const fs::path& cert_file, const std::string& common_name) {
  Identity id{key_file, cert_file, "", false};
  std::error_code ec;
  // The folders made for the identity are the owner's alone.
  for (const auto& file : {key_file, cert_file}) {
    const fs::path dir = file.parent_path();
    if (!dir.empty() && !fs::exists(dir, ec)) {
      fs::create_directories(dir, ec);
      if (ec) return make_error(dir.string() + ": cannot create: " + ec.message());
      fs::permissions(dir, fs::perms::owner_all, fs::perm_options::replace, ec);
    }
  }
  const bool have_key = fs::exists(key_file, ec);
  const bool have_cert = fs::exists(cert_file, ec);
  if (have_cert && !have_key) {
    return make_error(cert_file.string() + ": the rig's certificate is there but its key " + key_file.string() +
                      " is not; remove the certificate to make a new identity (clients then see a new fingerprint "
                      "and must pin it again)");
  }
  Key key;
  if (have_key) {
    auto k = load_key(key_file);
    if (!k) return k.error();
    key = std::move(*k);
  } else {
    key.reset(EVP_EC_gen("P-256"));
    if (!key) return make_error("cannot make the rig's TLS key (P-256)");
    Bio bio(BIO_new(BIO_s_mem()));
    if (!PEM_write_bio_PrivateKey(bio.get(), key.get(), nullptr, nullptr, 0, nullptr, nullptr)) {
      return make_error("cannot encode the rig's TLS key");
    }
    if (auto s = write_file_atomically(key_file, bio_text(bio.get()), 0600); !s) return s.error();
    id.created = true;
  }
  if (have_cert) {
    auto c = load_cert(cert_file);
    if (!c) return c.error();
    if (X509_check_private_key(c->get(), key.get()) != 1) {
      return make_error(cert_file.string() + " does not belong to the key " + key_file.string() +
                        "; remove both to make a new identity (clients then must pin it again)");
    }
    id.fingerprint = fingerprint_of(c->get());
    return id;
  }
  auto cert = make_certificate(key.get(), common_name);
  if (!cert) return cert.error();
  Bio bio(BIO_new(BIO_s_mem()));
  if (!PEM_write_bio_X509(bio.get(), cert->get())) return make_error("cannot encode the rig's certificate");
  if (auto s = write_file_atomically(cert_file, bio_text(bio.get()), 0600); !s) return s.error();
  id.fingerprint = fingerprint_of(cert->get());
  id.created = true;
  return id;
}

Expected<std::string> fingerprint_of_cert_file(const fs::path& cert_file) {
  auto c = load_cert(cert_file);
  if (!c) return c.error();
  return fingerprint_of(c->get());
}

fs::path default_known_rigs_file() {
  if (const char* f = std::getenv("VENEER_KNOWN_RIGS"); f && *f) return f;
  if (const char* x = std::getenv("XDG_CONFIG_HOME"); x && *x) return fs::path(x) / "veneer" / "known_rigs";
  const char* home = std::getenv("HOME");
  return fs::path(home && *home ? home : ".") / ".config" / "veneer" / "known_rigs";
}

namespace {
// The file's lines, and the index of `rig`'s (-1: none).
struct KnownLines {
  std::vector<std::string> lines;
  int at = -1;
  std::string fingerprint;
};
Expected<KnownLines> read_known(const fs::path& file, const std::string& rig) {
  KnownLines k;
  std::error_code ec;
  if (!fs::exists(file, ec)) return k;
  std::ifstream in(file);
  if (!in) return make_error(file.string() + ": cannot read the known-rigs file");
  std::string line;
  int n = 0;
  while (std::getline(in, line)) {
    ++n;
    std::istringstream words(line);
    std::string name, fp;
    words >> name >> fp;
    if (!name.empty() && name[0] != '#' && name == rig) {
      auto parsed = parse_fingerprint(fp);
      if (!parsed) return make_error(file.string() + ":" + std::to_string(n) + ": " + parsed.message());
      k.at = static_cast<int>(k.lines.size());
      k.fingerprint = *parsed;
    }
    k.lines.push_back(line);
  }
  return k;
}
}  // namespace

Expected<std::string> known_fingerprint(const fs::path& file, const std::string& rig) {
  auto k = read_known(file, rig);
  if (!k) return k.error();
  return k->fingerprint;
}

Status remember_fingerprint(const fs::path& file, const std::string& rig, const std::string& fingerprint) {
  auto fp = parse_fingerprint(fingerprint);
  if (!fp) return fp.error();
  if (rig.empty() || rig.find_first_of(" \t\r\n#") != std::string::npos) {
    return make_error("rig name '" + rig + "' cannot go into the known-rigs file (empty, blank or '#')");
  }
  auto k = read_known(file, rig);
  if (!k) return k.error();
  const std::string line = rig + " " + *fp;
  if (k->at >= 0) {
    k->lines[static_cast<size_t>(k->at)] = line;
  } else {
    if (k->lines.empty()) k->lines.push_back("# veneer: rigs whose certificate fingerprint is pinned (rig fingerprint)");
    k->lines.push_back(line);
  }
  std::string text;
  for (const auto& l : k->lines) text += l + "\n";
  return write_file_atomically(file, text, 0644);
}

}  // namespace veneer::tls
