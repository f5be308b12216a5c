// Lossless JPEG encoder (lj92.hpp), from ITU T.81: the prediction of Annex H
// (predictor 1, Ra; the first line predicted from the left, each line's first
// sample from the one above, the very first from 2^(P-1)), the difference
// coded as its magnitude category SSSS (Huffman) plus SSSS extra bits
// (Table H.2; SSSS 16 = -32768 with no extra bits), the code lengths of
// Annex K.2 with the adjustment to 16 bits of K.3, the codes of Annex C, and
// byte stuffing (0xFF is followed by 0x00) in the entropy-coded segment.
#include "lj92.hpp"

#include <algorithm>
#include <array>
#include <vector>

namespace veneer::io::detail {

namespace {

constexpr int kSymbols = 17;  // SSSS 0..16

inline int category(int diff) {
  const unsigned a = static_cast<unsigned>(diff < 0 ? -diff : diff);
  return a == 0 ? 0 : 32 - __builtin_clz(a);
}

// The prediction differences of the whole tile, in coding order, as wrapped
// 16-bit values (T.81 H.1.2.1: modulo 2^16, read as -32768..32767).
template <typename Visit>
void for_each_difference(const uint16_t* samples, int columns, int rows, int stride, int components, Visit visit) {
  for (int y = 0; y < rows; ++y) {
    const uint16_t* row = samples + static_cast<size_t>(y) * stride;
    const uint16_t* above = y > 0 ? row - stride : nullptr;
    for (int x = 0; x < columns; ++x) {
      int pred;
      if (x < components) {
        pred = above ? above[x] : 1 << 15;  // P = 16
      } else {
        pred = row[x - components];  // predictor 1: Ra, the same component one column left
      }
      visit(static_cast<int16_t>(static_cast<uint16_t>(row[x] - pred)));
    }
  }
}

struct Table {
  std::array<uint8_t, 17> bits{};  // bits[l]: codes of length l (1..16)
  std::vector<uint8_t> values;     // symbols by increasing code length
  std::array<uint16_t, kSymbols> code{};
  std::array<uint8_t, kSymbols> size{};
};

// Annex K.2 (code sizes from frequencies) and K.3 (limited to 16 bits), then
// Annex C (the codes).
Table make_table(const std::array<uint64_t, kSymbols>& counts) {
  constexpr int n = kSymbols + 1;  // plus the reserved symbol that keeps the all-ones code unused
  std::array<uint64_t, n> freq{};
  for (int i = 0; i < kSymbols; ++i) freq[i] = counts[i];
  freq[kSymbols] = 1;
  std::array<int, n> codesize{}, others;
  others.fill(-1);
  for (;;) {
    int v1 = -1, v2 = -1;
    for (int i = 0; i < n; ++i) {  // least frequency, largest symbol on ties
      if (freq[i] > 0 && (v1 < 0 || freq[i] <= freq[v1])) v1 = i;
    }
    for (int i = 0; i < n; ++i) {
      if (i != v1 && freq[i] > 0 && (v2 < 0 || freq[i] <= freq[v2])) v2 = i;
    }
    if (v2 < 0) break;
    freq[v1] += freq[v2];
    freq[v2] = 0;
    ++codesize[v1];
    while (others[v1] >= 0) {
      v1 = others[v1];
      ++codesize[v1];
    }
    others[v1] = v2;
    ++codesize[v2];
    while (others[v2] >= 0) {
      v2 = others[v2];
      ++codesize[v2];
    }
  }
  std::array<int, 40> bits{};
  for (int i = 0; i < n; ++i) {
    if (codesize[i] > 0) ++bits[codesize[i]];
  }
  for (int i = 39; i > 16; --i) {  // K.3: no code longer than 16 bits
    while (bits[i] > 0) {
      int j = i - 2;
      while (bits[j] == 0) --j;
      bits[i] -= 2;
      bits[i - 1] += 1;
      bits[j + 1] += 2;
      bits[j] -= 1;
    }
  }
  int longest = 16;
  while (bits[longest] == 0) --longest;
  bits[longest] -= 1;  // the reserved symbol's code goes

  Table t;
  for (int l = 1; l <= 16; ++l) t.bits[l] = static_cast<uint8_t>(bits[l]);
  for (int l = 1; l <= 32; ++l) {
    for (int s = 0; s < kSymbols; ++s) {
      if (codesize[s] == l) t.values.push_back(static_cast<uint8_t>(s));
    }
  }
  // Annex C: sizes in order, then consecutive codes.
  uint32_t code = 0;
  size_t k = 0;
  for (int l = 1; l <= 16; ++l) {
    for (int c = 0; c < t.bits[l]; ++c, ++k) {
      t.code[t.values[k]] = static_cast<uint16_t>(code++);
      t.size[t.values[k]] = static_cast<uint8_t>(l);
    }
    code <<= 1;
  }
  return t;
}

class BitWriter {
 public:
  explicit BitWriter(std::string& out) : out_(out) {}
  void put(uint32_t value, int count) {  // count <= 32
    if (count == 0) return;
    acc_ = (acc_ << count) | (value & ((count == 32 ? 0 : (uint64_t{1} << count)) - 1) & 0xffffffffu);
    n_ += count;
    while (n_ >= 8) {
      n_ -= 8;
      const char byte = static_cast<char>((acc_ >> n_) & 0xff);
      out_.push_back(byte);
      if (byte == static_cast<char>(0xff)) out_.push_back('\0');  // byte stuffing
    }
  }
  void flush() {  // pad with 1 bits (T.81 F.1.2.3)
    if (n_ > 0) put((1u << (8 - n_)) - 1, 8 - n_);
  }

 private:
  std::string& out_;
  uint64_t acc_ = 0;
  int n_ = 0;
};

void marker(std::string& out, uint8_t m) {
  out.push_back(static_cast<char>(0xff));
  out.push_back(static_cast<char>(m));
}
void put16(std::string& out, unsigned v) {
  out.push_back(static_cast<char>((v >> 8) & 0xff));
  out.push_back(static_cast<char>(v & 0xff));
}

}  // namespace

void encode_lossless_jpeg(const uint16_t* samples, int columns, int rows, int stride, int components,
                          std::string& out) {
  std::array<uint64_t, kSymbols> counts{};
  for_each_difference(samples, columns, rows, stride, components, [&](int diff) { ++counts[category(diff)]; });
  const Table t = make_table(counts);

  marker(out, 0xd8);  // SOI
  marker(out, 0xc4);  // DHT: one DC table, class 0, id 0
  put16(out, static_cast<unsigned>(2 + 1 + 16 + t.values.size()));
  out.push_back('\0');
  for (int l = 1; l <= 16; ++l) out.push_back(static_cast<char>(t.bits[l]));
  for (uint8_t v : t.values) out.push_back(static_cast<char>(v));
  marker(out, 0xc3);  // SOF3: lossless, Huffman
  put16(out, static_cast<unsigned>(8 + 3 * components));
  out.push_back(16);  // P
  put16(out, static_cast<unsigned>(rows));
  put16(out, static_cast<unsigned>(columns / components));
  out.push_back(static_cast<char>(components));
  for (int c = 0; c < components; ++c) {
    out.push_back(static_cast<char>(c + 1));  // Ci
    out.push_back(0x11);                      // H = V = 1
    out.push_back(0);                         // Tq
  }
  marker(out, 0xda);  // SOS
  put16(out, static_cast<unsigned>(6 + 2 * components));
  out.push_back(static_cast<char>(components));
  for (int c = 0; c < components; ++c) {
    out.push_back(static_cast<char>(c + 1));
    out.push_back(0x00);  // table 0
  }
  out.push_back(1);  // Ss: predictor 1
  out.push_back(0);  // Se
  out.push_back(0);  // Ah, Al (point transform 0)

  BitWriter bits(out);
  for_each_difference(samples, columns, rows, stride, components, [&](int diff) {
    const int s = category(diff);
    if (s == 0 || s == 16) {
      bits.put(t.code[s], t.size[s]);
      return;
    }
    const uint32_t extra = static_cast<uint32_t>(diff < 0 ? diff + (1 << s) - 1 : diff);  // H.1.2.2
    bits.put((static_cast<uint32_t>(t.code[s]) << s) | (extra & ((1u << s) - 1)), t.size[s] + s);
  });
  bits.flush();
  marker(out, 0xd9);  // EOI
}

}  // namespace veneer::io::detail
