#pragma once
// The error family of cutsim. Every error knows the exit code the CLI returns
// for it (sysexits.h values) and, where there is one, the place in an input
// file it refers to.
#include <string>
#include <stdexcept>

namespace cutsim {

/// sysexits.h codes used by the CLI.
enum class ExitCode : int {
  ok = 0,
  contacts = 1,      ///< the run succeeded but found tool contacts (later issues)
  usage = 64,        ///< bad command line
  data = 65,         ///< malformed input data (G-code, meshes)
  no_input = 66,     ///< an input file is missing or unreadable
  software = 70,     ///< internal error
  cannot_create = 73,///< an output file or directory cannot be created
  config = 78,       ///< bad job, tool or machine configuration
  interrupted = 130, ///< stopped by SIGINT (143 for SIGTERM: 128 + signal)
};

/// A place in an input file; line and column are 1-based, 0 means "none".
struct SourceLocation {
  std::string file;
  int line = 0;
  int column = 0;
  std::string source_line;  ///< the text of that line, for the caret display
};

/// Base of all cutsim errors.
class Error : public std::runtime_error {
public:
  Error(ExitCode code, SourceLocation where, const std::string& message);
  ExitCode code() const { return code_; }
  const SourceLocation& where() const { return where_; }
  const std::string& message() const { return message_; }
  /// `file:line:col: error: message`, then the source line and a caret under
  /// the column when both are known.
  std::string format() const;

private:
  ExitCode code_;
  SourceLocation where_;
  std::string message_;
};

/// Malformed input data (a G-code word, a mesh); exit 65.
class ParseError : public Error {
public:
  ParseError(SourceLocation where, const std::string& message)
      : Error(ExitCode::data, std::move(where), message) {}
};

/// Bad job, tool or machine settings; exit 78.
class ConfigError : public Error {
public:
  ConfigError(SourceLocation where, const std::string& message)
      : Error(ExitCode::config, std::move(where), message) {}
};

/// A missing or unreadable input file; exit 66.
class InputError : public Error {
public:
  InputError(const std::string& file, const std::string& message)
      : Error(ExitCode::no_input, SourceLocation{file, 0, 0, {}}, message) {}
};

/// An output that cannot be created; exit 73.
class OutputError : public Error {
public:
  OutputError(const std::string& file, const std::string& message)
      : Error(ExitCode::cannot_create, SourceLocation{file, 0, 0, {}}, message) {}
};

/// Geometry that cannot be handled (degenerate tool, job too large); exit 65.
class GeometryError : public Error {
public:
  GeometryError(SourceLocation where, const std::string& message)
      : Error(ExitCode::data, std::move(where), message) {}
};

/// The run was stopped by a signal; exit 128 + signal.
class InterruptedError : public Error {
public:
  InterruptedError(SourceLocation where, int signal, const std::string& message)
      : Error(ExitCode::interrupted, std::move(where), message), signal_(signal) {}
  int exit_status() const { return 128 + signal_; }

private:
  int signal_;
};

/// Command-line misuse; exit 64.
class UsageError : public Error {
public:
  explicit UsageError(const std::string& message)
      : Error(ExitCode::usage, SourceLocation{}, message) {}
};

}  // namespace cutsim
