// The one error type for bad scene input: it names the file, the element and the reason.
#pragma once

#include <stdexcept>
#include <string>

namespace tessera {

class SceneError : public std::runtime_error {
 public:
  SceneError(std::string file, std::string element, std::string reason)
      : std::runtime_error(file + ": " + (element.empty() ? "" : element + ": ") + reason),
        file_(std::move(file)),
        element_(std::move(element)),
        reason_(std::move(reason)) {}
  const std::string& file() const { return file_; }
  const std::string& element() const { return element_; }
  const std::string& reason() const { return reason_; }

 private:
  std::string file_, element_, reason_;
};

}  // namespace tessera
