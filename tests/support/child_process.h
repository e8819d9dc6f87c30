// `trephine ARGS` as a child process whose stdout a test reads line by line: a server started as a
// user starts it, to be killed (SIGKILL, SIGTERM) at the moment a test chooses.
#pragma once

#include <csignal>
#include <cstdio>
#include <string>
#include <sys/wait.h>
#include <unistd.h>
#include <vector>

namespace trephine::testing {

#ifdef TREPHINE_BIN
struct Child {
    pid_t pid = -1;
    FILE* out = nullptr;

    explicit Child(std::vector<std::string> args) {
        int fds[2];
        if (pipe(fds) != 0)
            return;
        args.insert(args.begin(), TREPHINE_BIN);
        pid = fork();
        if (pid == 0) {
            dup2(fds[1], 1);
            close(fds[0]);
            std::vector<char*> argv;
            for (std::string& a : args)
                argv.push_back(a.data());
            argv.push_back(nullptr);
            execv(TREPHINE_BIN, argv.data());
            _exit(127);
        }
        close(fds[1]);
        out = fdopen(fds[0], "r");
    }
    ~Child() {
        if (pid > 0)
            end(SIGKILL);
    }
    Child(const Child&) = delete;
    Child& operator=(const Child&) = delete;

    std::string line() {
        char buf[1024] = {};
        return out && fgets(buf, sizeof buf, out) ? std::string(buf) : std::string();
    }
    // The port of its "... on port N ..." line (-1 when it printed none).
    int port() {
        for (std::string l = line(); !l.empty(); l = line())
            if (const auto at = l.find("on port "); at != std::string::npos)
                return std::stoi(l.substr(at + 8));
        return -1;
    }
    // The first line holding `text` ("" when the output ended first).
    std::string waitFor(const std::string& text) {
        for (std::string l = line(); !l.empty(); l = line())
            if (l.find(text) != std::string::npos)
                return l;
        return {};
    }
    // `sig`, then its exit status (-1: killed by a signal).
    int end(int sig) {
        kill(pid, sig);
        int status = 0;
        waitpid(pid, &status, 0);
        pid = -1;
        if (out)
            fclose(out);
        out = nullptr;
        return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    }
};
#endif

} // namespace trephine::testing
