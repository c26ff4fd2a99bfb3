#pragma once
// Errors cross module boundaries as exceptions; only cli/ turns them into exit codes (docs/hardening.md).
//   InputError    -> exit 2: the user's data or options are wrong (names the file and the problem).
//   ResourceError -> exit 3: the machine: the disk is full, a quota or file-size limit is reached,
//                    the device fails. Nothing is wrong with the job; it resumes once fixed.
//   Interrupted   -> exit 128 + the signal: SIGINT/SIGTERM stopped a job at a safe point after a
//                    checkpoint; it resumes.
//   anything else -> exit 1: an internal error.
#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <string>

namespace sf {

class InputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class ResourceError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// A stop request (FusionHooks::stop, set by SIGINT/SIGTERM) ended the work at a safe point; the
// job's journal holds a checkpoint of everything finished.
class Interrupted : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// True for the errno values that mean the machine ran out of something or failed, not that the
// user named a wrong path.
inline bool is_resource_errno(int err) {
  return err == ENOSPC || err == EDQUOT || err == EFBIG || err == EIO || err == EROFS || err == ENOMEM;
}

// A failed write of `path` ("path: what: strerror"): ResourceError for the machine's conditions,
// InputError otherwise (e.g. an output folder the user cannot write).
[[noreturn]] inline void throw_write_error(const std::string& path, const std::string& what, int err) {
  const std::string message = path + ": " + what + ": " + (err ? std::strerror(err) : "unknown error");
  if (is_resource_errno(err)) throw ResourceError(message);
  throw InputError(message);
}

// "path: what is wrong" — the one-line form every reader uses.
inline InputError input_error(const std::string& path, const std::string& what) {
  return InputError(path + ": " + what);
}

}  // namespace sf
