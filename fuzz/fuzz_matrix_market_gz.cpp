// strata fuzz target — the gzip path of the Matrix Market reader, on structured text.
//
// What. The input is [c][text]: `text` is gzip-compressed in memory (zlib deflate with a
// gzip header), so the mutations act on the Matrix Market text while the reader goes
// through decompression. Checks, beyond mm_checks.hpp:
//   * the compressed file reads exactly like the plain text (same matrix, or the same
//     error message: both files have the same path);
//   * when c < 128 the compressed file is cut to c/128 of its length: a truncated gzip
//     file must be a ParseError, never a matrix (Z_BUF_ERROR detection in LineReader) —
//     or the NotSupported the whole text gives, when the part that decompresses already
//     names a kind the reader refuses (found by this target: a cut "hermitian" file;
//     when the text declares dimensions too large to read here, the banner line alone
//     gives the refusal expected).
// Seeds: fuzz/corpus/matrix_market_gz (a leading byte 0xff, "do not cut", then a small
// Matrix Market text).
#include <zlib.h>

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "fuzz_common.hpp"
#include "mm_checks.hpp"

namespace {

std::vector<uint8_t> gzip(const uint8_t* data, size_t size) {
  z_stream z{};
  // windowBits 15 + 16: a gzip header and trailer instead of zlib's
  if (deflateInit2(&z, 6, Z_DEFLATED, 15 + 16, 8, Z_DEFAULT_STRATEGY) != Z_OK) std::abort();
  std::vector<uint8_t> out(deflateBound(&z, size) + 64);
  z.next_in = const_cast<Bytef*>(data);
  z.avail_in = static_cast<uInt>(size);
  z.next_out = out.data();
  z.avail_out = static_cast<uInt>(out.size());
  if (deflate(&z, Z_FINISH) != Z_STREAM_END) std::abort();
  out.resize(z.total_out);
  deflateEnd(&z);
  return out;
}

bool same(const strata::SparseMatrix& a, const strata::SparseMatrix& b) {
  return a.n_rows == b.n_rows && a.n_cols == b.n_cols && a.storage == b.storage &&
         a.offsets == b.offsets && a.indices == b.indices && a.values == b.values;
}

// The reader's message for a file holding only the first line of TEXT (the banner), or ""
// when it reads; the file is INPUT, so the path in the message is the same.
std::string banner_error(strata::fuzz::ScratchFile& input, const uint8_t* text, size_t n) {
  size_t end = 0;
  while (end < n && text[end] != '\n') ++end;
  try {
    (void)strata::read_matrix_market(input.write(text, end < n ? end + 1 : n));
  } catch (const strata::Error& e) {
    return e.what();
  }
  return "";
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace strata::fuzz;
  static ScratchFile input(".mtx.gz"), scratch(".out.mtx");
  if (size == 0) return 0;
  const uint8_t cut = data[0];
  const uint8_t* text = data + 1;
  const size_t n = size - 1;

  strata::MMMatrix plain, packed;
  std::string plain_error, packed_error;
  const bool plain_ok = check_file(input.write(text, n), scratch.path(), &plain, &plain_error);
  std::vector<uint8_t> z = gzip(text, n);
  // text that is itself gzip data is decompressed when read plain: nothing to compare
  const bool nested = n >= 2 && text[0] == 0x1f && text[1] == 0x8b;
  if (cut >= 128 && !nested) {
    const bool packed_ok =
        check_file(input.write(z.data(), z.size()), scratch.path(), &packed, &packed_error);
    require(plain_ok == packed_ok, "plain and gzip files: one reads, the other does not");
    if (plain_ok) require(same(plain.matrix, packed.matrix), "plain and gzip: other matrices");
    if (!plain_ok && plain_error != packed_error)
      finding("plain and gzip files: other errors\n  " + plain_error + "\n  " + packed_error);
  } else if (cut < 128) {
    z.resize(z.size() * cut / 128);
    try {
      (void)strata::read_matrix_market(input.write(z.data(), z.size()));
      finding("a truncated gzip file was read without error");
    } catch (const strata::ParseError&) {
    } catch (const strata::NotSupported& e) {
      // the part that decompresses can already name a kind the reader refuses (a
      // "hermitian" header): the same refusal as the whole text's, before any truncation
      // is reached, is right. When the text's dimensions were too large to read here
      // ("skipped"), the refusal expected is the banner line's alone.
      if (plain_error == "skipped") plain_error = banner_error(input, text, n);
      if (plain_ok || plain_error != e.what())
        finding(std::string("a truncated gzip file gave NotSupported unlike its text: ") +
                e.what());
    } catch (const strata::Error& e) {
      finding(std::string("a truncated gzip file gave an error other than ParseError: ") +
              e.what());
    }
  }
  return 0;
}
