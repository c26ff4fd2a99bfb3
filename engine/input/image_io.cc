// libpng and libjpeg report errors by longjmp. Each decoder therefore runs in one function that
// calls setjmp and holds no object with a destructor that is created after the setjmp, and turns a
// failure into an InputError only after libpng/libjpeg have been torn down.
#include "engine/input/image_io.h"

#include <jpeglib.h>
#include <png.h>

#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <string>

#include "engine/error.h"
#include "engine/input/file_util.h"

namespace sf {
namespace {

namespace fs = std::filesystem;
using input_detail::read_file_bytes;

// Decoded size limit against the file size, so that a corrupt header cannot make us allocate
// gigabytes. Deflate cannot expand by more than ~1032:1, and baseline JPEG of a flat image stays
// well below 2000:1; the slack covers tiny files.
constexpr std::uint64_t kMaxExpansion = 2048;
constexpr std::uint64_t kSlackBytes = 1 << 20;
constexpr std::uint64_t kMaxDecodedBytes = std::uint64_t(1) << 32;

void check_decoded_size(const fs::path& path, std::uint64_t w, std::uint64_t h, std::uint64_t bytes_per_pixel,
                        std::size_t file_size) {
  if (w == 0 || h == 0) throw input_error(path.string(), "image has zero width or height");
  const std::uint64_t decoded = w * h * bytes_per_pixel;
  if (decoded > kMaxDecodedBytes || decoded > kMaxExpansion * file_size + kSlackBytes)
    throw input_error(path.string(), "image header claims " + std::to_string(w) + "x" + std::to_string(h) +
                                         " pixels, impossible for a file of " + std::to_string(file_size) + " bytes");
}

bool is_png(const std::vector<std::uint8_t>& b) { return b.size() >= 8 && png_sig_cmp(b.data(), 0, 8) == 0; }
bool is_jpeg(const std::vector<std::uint8_t>& b) { return b.size() >= 3 && b[0] == 0xFF && b[1] == 0xD8 && b[2] == 0xFF; }

// ---------------------------------------------------------------------------------------------
// PNG

struct PngReadState {
  const std::uint8_t* data = nullptr;
  std::size_t size = 0, pos = 0;
  char message[256] = {0};
};

void png_read_from_memory(png_structp png, png_bytep out, png_size_t n) {
  auto* s = static_cast<PngReadState*>(png_get_io_ptr(png));
  if (n > s->size - s->pos) png_error(png, "file is truncated");
  std::memcpy(out, s->data + s->pos, n);
  s->pos += n;
}

void png_error_to_state(png_structp png, png_const_charp msg) {
  auto* s = static_cast<PngReadState*>(png_get_error_ptr(png));
  std::snprintf(s->message, sizeof(s->message), "%s", msg);
  png_longjmp(png, 1);
}
void png_ignore_warning(png_structp, png_const_charp) {}

enum class PngWant { Rgb8, Grey16 };

struct PngHeader {
  png_uint_32 width = 0, height = 0;
  int bit_depth = 0, colour_type = 0;
};

// Decodes into `out` (bytes, row-major, tightly packed). Returns "" or an error: "size" and
// "format" are header problems the caller reports with the numbers in `header`.
// `rows` is scratch owned by the caller, so that no object with a destructor lives only in this
// frame after the setjmp.
std::string decode_png(const std::vector<std::uint8_t>& file, PngWant want, std::vector<std::uint8_t>* out,
                       PngHeader* header, std::vector<png_bytep>* rows) {
  PngReadState state;
  state.data = file.data();
  state.size = file.size();
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &state, png_error_to_state, png_ignore_warning);
  if (!png) return "out of memory";
  png_infop info = png_create_info_struct(png);
  if (!info) {
    png_destroy_read_struct(&png, nullptr, nullptr);
    return "out of memory";
  }
  // Everything modified after setjmp and used after a longjmp is reached through a pointer
  // (`state`, whose address libpng holds, and the caller's `out`, `header`, `rows`).
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_read_struct(&png, &info, nullptr);
    return std::string("corrupt PNG (") + state.message + ")";
  }
  png_set_read_fn(png, &state, png_read_from_memory);
  png_read_info(png, info);
  header->width = png_get_image_width(png, info);
  header->height = png_get_image_height(png, info);
  header->bit_depth = png_get_bit_depth(png, info);
  header->colour_type = png_get_color_type(png, info);
  const std::uint64_t bpp = want == PngWant::Rgb8 ? 3 : 2;
  const std::uint64_t decoded = std::uint64_t(header->width) * header->height * bpp;
  if (header->width == 0 || header->height == 0 || decoded > kMaxDecodedBytes ||
      decoded > kMaxExpansion * file.size() + kSlackBytes) {
    png_destroy_read_struct(&png, &info, nullptr);
    return "size";  // the caller reports it with the numbers
  }
  if (want == PngWant::Grey16) {
    if (header->colour_type != PNG_COLOR_TYPE_GRAY || header->bit_depth != 16) {
      png_destroy_read_struct(&png, &info, nullptr);
      return "format";
    }
    png_set_swap(png);  // PNG stores 16-bit big-endian; we want host order
  } else {
    if (header->colour_type == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
    if (header->colour_type == PNG_COLOR_TYPE_GRAY && header->bit_depth < 8) png_set_expand_gray_1_2_4_to_8(png);
    if (header->bit_depth == 16) png_set_strip_16(png);
    if (header->colour_type == PNG_COLOR_TYPE_GRAY || header->colour_type == PNG_COLOR_TYPE_GRAY_ALPHA)
      png_set_gray_to_rgb(png);
    png_set_strip_alpha(png);  // also drops tRNS-derived alpha: colour only
  }
  png_set_interlace_handling(png);
  png_read_update_info(png, info);
  const std::size_t rowbytes = png_get_rowbytes(png, info);
  if (rowbytes != header->width * bpp) {
    png_destroy_read_struct(&png, &info, nullptr);
    return "unexpected row size after conversion";
  }
  out->resize(rowbytes * header->height);
  rows->resize(header->height);
  for (png_uint_32 r = 0; r < header->height; ++r) (*rows)[r] = out->data() + r * rowbytes;
  png_read_image(png, rows->data());
  png_read_end(png, nullptr);
  png_destroy_read_struct(&png, &info, nullptr);
  return "";
}

void throw_png_error(const fs::path& path, const std::string& err, const PngHeader& h, std::size_t file_size,
                     PngWant want) {
  if (err == "size") check_decoded_size(path, h.width, h.height, want == PngWant::Rgb8 ? 3 : 2, file_size);
  if (err == "format")
    throw input_error(path.string(), "expected a 16-bit single-channel PNG, found bit depth " +
                                         std::to_string(h.bit_depth) + ", colour type " + std::to_string(h.colour_type));
  throw input_error(path.string(), err);
}

struct PngWriteState {
  std::FILE* file = nullptr;
  char message[256] = {0};
};

void png_write_error(png_structp png, png_const_charp msg) {
  auto* s = static_cast<PngWriteState*>(png_get_error_ptr(png));
  std::snprintf(s->message, sizeof(s->message), "%s", msg);
  png_longjmp(png, 1);
}

// Writes rows of `bytes_per_row`; `bit_depth` 8 or 16 (16-bit samples given in host order).
std::string encode_png(std::FILE* file, int width, int height, int colour_type, int bit_depth, const std::uint8_t* data,
                       std::size_t bytes_per_row) {
  PngWriteState state;
  state.file = file;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &state, png_write_error, png_ignore_warning);
  if (!png) return "out of memory";
  png_infop info = png_create_info_struct(png);
  if (!info) {
    png_destroy_write_struct(&png, nullptr);
    return "out of memory";
  }
  if (setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    return state.message;
  }
  png_init_io(png, file);
  png_set_IHDR(png, info, width, height, bit_depth, colour_type, PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_DEFAULT,
               PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  if (bit_depth == 16) png_set_swap(png);
  for (int r = 0; r < height; ++r) png_write_row(png, const_cast<png_bytep>(data + std::size_t(r) * bytes_per_row));
  png_write_end(png, nullptr);
  png_destroy_write_struct(&png, &info);
  return "";
}

void write_png_atomically(const fs::path& path, int width, int height, int colour_type, int bit_depth,
                          const std::uint8_t* data, std::size_t bytes_per_row) {
  const fs::path tmp = input_detail::temp_sibling(path);
  std::FILE* file = std::fopen(tmp.c_str(), "wb");
  if (!file) throw std::runtime_error(path.string() + ": cannot create file");
  std::string err = encode_png(file, width, height, colour_type, bit_depth, data, bytes_per_row);
  if (std::fclose(file) != 0 && err.empty()) err = "cannot write file";
  if (!err.empty()) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw std::runtime_error(path.string() + ": cannot write PNG (" + err + ")");
  }
  input_detail::commit_temp(tmp, path);
}

// ---------------------------------------------------------------------------------------------
// JPEG

struct JpegError {
  jpeg_error_mgr mgr;
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX] = {0};
};

void jpeg_error_exit(j_common_ptr cinfo) {
  auto* err = reinterpret_cast<JpegError*>(cinfo->err);
  (*cinfo->err->format_message)(cinfo, err->message);
  std::longjmp(err->jump, 1);
}
void jpeg_no_output(j_common_ptr) {}

struct JpegHeader {
  unsigned width = 0, height = 0;
};

std::string decode_jpeg(const std::vector<std::uint8_t>& file, std::vector<std::uint8_t>* out, JpegHeader* header) {
  jpeg_decompress_struct cinfo;
  JpegError err;
  cinfo.err = jpeg_std_error(&err.mgr);
  err.mgr.error_exit = jpeg_error_exit;
  err.mgr.output_message = jpeg_no_output;
  if (setjmp(err.jump)) {
    jpeg_destroy_decompress(&cinfo);
    return std::string("corrupt JPEG (") + err.message + ")";
  }
  jpeg_create_decompress(&cinfo);
  jpeg_mem_src(&cinfo, file.data(), static_cast<unsigned long>(file.size()));
  jpeg_read_header(&cinfo, TRUE);
  cinfo.out_color_space = JCS_RGB;  // libjpeg converts grey and YCbCr; CMYK fails and is reported
  header->width = cinfo.image_width;
  header->height = cinfo.image_height;
  const std::uint64_t decoded = std::uint64_t(header->width) * header->height * 3;
  if (header->width == 0 || header->height == 0 || decoded > kMaxDecodedBytes ||
      decoded > kMaxExpansion * file.size() + kSlackBytes) {
    jpeg_destroy_decompress(&cinfo);
    return "size";
  }
  jpeg_start_decompress(&cinfo);
  if (cinfo.output_components != 3) {
    jpeg_destroy_decompress(&cinfo);
    return "unsupported JPEG colour space";
  }
  const std::size_t stride = std::size_t(cinfo.output_width) * 3;
  out->resize(stride * cinfo.output_height);
  while (cinfo.output_scanline < cinfo.output_height) {
    JSAMPROW row = out->data() + std::size_t(cinfo.output_scanline) * stride;
    jpeg_read_scanlines(&cinfo, &row, 1);
  }
  jpeg_finish_decompress(&cinfo);
  jpeg_destroy_decompress(&cinfo);
  return "";
}

}  // namespace

Image8 read_image_rgb(const fs::path& path) {
  const std::vector<std::uint8_t> file = read_file_bytes(path);
  Image8 image;
  image.channels = 3;
  if (is_png(file)) {
    PngHeader h;
    std::vector<png_bytep> rows;
    const std::string err = decode_png(file, PngWant::Rgb8, &image.data, &h, &rows);
    if (!err.empty()) throw_png_error(path, err, h, file.size(), PngWant::Rgb8);
    image.width = int(h.width);
    image.height = int(h.height);
    return image;
  }
  if (is_jpeg(file)) {
    JpegHeader h;
    const std::string err = decode_jpeg(file, &image.data, &h);
    if (err == "size") check_decoded_size(path, h.width, h.height, 3, file.size());
    if (!err.empty()) throw input_error(path.string(), err);
    image.width = int(h.width);
    image.height = int(h.height);
    return image;
  }
  throw input_error(path.string(), "not a PNG or JPEG file");
}

Image16 read_png16(const fs::path& path) {
  const std::vector<std::uint8_t> file = read_file_bytes(path);
  if (!is_png(file)) throw input_error(path.string(), "not a PNG file");
  PngHeader h;
  std::vector<std::uint8_t> bytes;
  std::vector<png_bytep> rows;
  const std::string err = decode_png(file, PngWant::Grey16, &bytes, &h, &rows);
  if (!err.empty()) throw_png_error(path, err, h, file.size(), PngWant::Grey16);
  Image16 image;
  image.width = int(h.width);
  image.height = int(h.height);
  image.data.resize(std::size_t(h.width) * h.height);
  std::memcpy(image.data.data(), bytes.data(), bytes.size());
  return image;
}

void write_png8(const fs::path& path, const Image8& image) {
  if (image.channels != 1 && image.channels != 3)
    throw std::invalid_argument(path.string() + ": write_png8 needs 1 or 3 channels, got " +
                                std::to_string(image.channels));
  const std::size_t stride = std::size_t(image.width) * image.channels;
  if (image.width <= 0 || image.height <= 0 || image.data.size() != stride * image.height)
    throw std::invalid_argument(path.string() + ": write_png8 given an image whose data does not match its size");
  write_png_atomically(path, image.width, image.height, image.channels == 1 ? PNG_COLOR_TYPE_GRAY : PNG_COLOR_TYPE_RGB,
                       8, image.data.data(), stride);
}

void write_png16(const fs::path& path, const Image16& image) {
  const std::size_t n = std::size_t(image.width) * image.height;
  if (image.width <= 0 || image.height <= 0 || image.data.size() != n)
    throw std::invalid_argument(path.string() + ": write_png16 given an image whose data does not match its size");
  write_png_atomically(path, image.width, image.height, PNG_COLOR_TYPE_GRAY, 16,
                       reinterpret_cast<const std::uint8_t*>(image.data.data()), std::size_t(image.width) * 2);
}

}  // namespace sf
