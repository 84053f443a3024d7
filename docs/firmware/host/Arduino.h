#pragma once
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <stdlib.h>
#include <ctype.h>
#include <time.h>
#include <unistd.h>
#include <fcntl.h>
#define LOW 0
#define HIGH 1
#define OUTPUT 1
#define INPUT_PULLUP 2
#define RISING 3
static inline unsigned long millis(){ struct timespec t; clock_gettime(CLOCK_MONOTONIC,&t); return t.tv_sec*1000UL+t.tv_nsec/1000000UL; }
static inline void pinMode(int,int){}
static inline void analogWrite(int,int){}
static inline int digitalRead(int){return HIGH;}
static inline int digitalPinToInterrupt(int p){return p;}
static inline void attachInterrupt(int, void(*)(), int){}
static inline void noInterrupts(){}
static inline void interrupts(){}
template<class T> T constrain(T x, T a, T b){ return x<a?a:(x>b?b:x); }
struct SerialT { int pk=-1;
  void begin(unsigned long){ fcntl(0,F_SETFL,O_NONBLOCK); }
  int available(){ if(pk>=0) return 1; unsigned char c; if(::read(0,&c,1)==1){pk=c;return 1;} return 0; }
  int read(){ int c=pk; pk=-1; return c; }
  void write(const char*s){ fputs(s,stdout); fflush(stdout);} };
static SerialT Serial;
