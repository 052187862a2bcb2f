// Error types thrown by the lfnet library. The program catches them and prints one line.
#pragma once

#include <sstream>
#include <stdexcept>
#include <string>

namespace lfnet {

// Base of every lfnet error.
class Error : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// A configuration value or JSON document is invalid; the message names the JSON path.
class ConfigError : public Error {
 public:
  using Error::Error;
};

// A file or folder could not be read or written, or has the wrong content.
class IoError : public Error {
 public:
  using Error::Error;
};

// A checkpoint is truncated, foreign, of another format version, architecture or Phi.
class CheckpointError : public Error {
 public:
  using Error::Error;
};

// A computation produced NaN or inf, or cannot proceed on the given numbers.
class NumericalError : public Error {
 public:
  using Error::Error;
};

namespace detail {
template <typename... Args>
std::string concat(const Args&... args) {
  std::ostringstream out;
  (out << ... << args);
  return out.str();
}
}  // namespace detail

}  // namespace lfnet

// Throws ErrorType with the message parts and the throwing file:line when cond is false.
#define LFNET_CHECK_AS(ErrorType, cond, ...)                                                     \
  do {                                                                                           \
    if (!(cond)) {                                                                               \
      throw ErrorType(::lfnet::detail::concat(__VA_ARGS__, " [", __FILE__, ":", __LINE__, "]")); \
    }                                                                                            \
  } while (false)

// Internal invariant or argument check; throws lfnet::Error.
#define LFNET_CHECK(cond, ...) LFNET_CHECK_AS(::lfnet::Error, cond, __VA_ARGS__)
