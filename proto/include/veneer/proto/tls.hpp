#pragma once
// The rig API's TLS identity (proto/README.md, "Encryption and pinning"):
// the rig's key and self-signed certificate, the fingerprint people compare
// (SHA-256 of the certificate's DER, upper-case hex pairs joined by ':', as
// `openssl x509 -noout -fingerprint -sha256` prints it), and the known-rigs
// file a client pins fingerprints in. OpenSSL stays inside tls.cpp; the asio
// SSL contexts are made by the server and the client themselves.
#include <filesystem>
#include <string>
#include <vector>

#include "veneer/util/expected.hpp"

namespace veneer::tls {

// "AB:01:...": SHA-256 of `der`, 32 upper-case hex pairs joined by ':' (95 characters).
std::string fingerprint_of_der(const unsigned char* der, size_t size);

// A fingerprint as a person or a file gives it: 64 hex digits in any case,
// with or without ':' (or spaces) between pairs. Returns the canonical form;
// an error naming the text when it is not 64 hex digits.
Expected<std::string> parse_fingerprint(const std::string& text);

// The rig's identity on disk.
struct Identity {
  std::filesystem::path key_file;   // PEM, PKCS#8 private key (ECDSA P-256), mode 0600
  std::filesystem::path cert_file;  // PEM, the self-signed X.509 certificate, mode 0600
  std::string fingerprint;          // of the certificate
  bool created = false;             // made by this call
};

// Reads the key and certificate, or makes them when neither exists: a new
// P-256 key, a self-signed certificate (CN = `common_name`, serial random,
// valid from a day ago until 9999-12-31, as RFC 5280 says for "no end"),
// each written to a temporary file (0600), synced and renamed into place.
// A key without its certificate gets a new certificate; a certificate
// without its key, or a pair that does not match, is an error naming the
// files (nothing is replaced: clients would see a new fingerprint).
Expected<Identity> ensure_identity(const std::filesystem::path& key_file, const std::filesystem::path& cert_file,
                                   const std::string& common_name);

// The fingerprint of a PEM certificate file.
Expected<std::string> fingerprint_of_cert_file(const std::filesystem::path& cert_file);

// ---- the known-rigs file (client side): one line per rig,
//   <rig> <fingerprint>
// where <rig> is how the client names it ("host:port", "[v6]:port"); '#'
// starts a comment line. Written whole to a temporary file and renamed.

// $VENEER_KNOWN_RIGS, else $XDG_CONFIG_HOME/veneer/known_rigs, else ~/.config/veneer/known_rigs.
std::filesystem::path default_known_rigs_file();
// The pinned fingerprint of `rig`, "" when the file or the line does not exist;
// an error when the file cannot be read or the rig's line is malformed.
Expected<std::string> known_fingerprint(const std::filesystem::path& file, const std::string& rig);
// Pins `fingerprint` for `rig` (replacing its line, keeping the others).
Status remember_fingerprint(const std::filesystem::path& file, const std::string& rig, const std::string& fingerprint);

// Writes `bytes` to `file` atomically: a temporary file beside it with
// `mode`, synced, renamed over `file`, the folder synced.
Status write_file_atomically(const std::filesystem::path& file, const std::string& bytes, unsigned mode);

}  // namespace veneer::tls
